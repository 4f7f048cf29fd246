//! Actions of a rigged character: joint rotations as functions of clip time τ ∈ [0, 1], drawn speeds,
//! amplitudes and directions, and the caption that says what happens.
//!
//! Rotations are about the canonical axes (x forward, y up, z right): about z by a positive angle swings a hanging
//! limb forward; about y by a positive angle turns the body to its left; about x by −side · θ lifts a limb of that
//! side outwards.

use std::f32::consts::{PI, TAU};

use super::{Chain, Pose, Rig, Template};
use crate::rng::{DataRng, Rng};

/// What a rigged character does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Action {
    /// A walking gait: legs in their template's phase pattern, arms swinging against them.
    Walk,
    /// A faster gait with more swing, a forward lean and a bounce.
    Run,
    /// Crouch, leap (in place or forward) and land.
    Jump,
    /// Turn in place by 60–180 degrees, stepping.
    Turn,
    /// Wind up and strike: an arm swing, a bite, a peck, a strike with the front legs.
    Attack,
    /// An arm waving, a tail wagging, antennae or wings moving in place.
    Wave,
    /// Fall over (forward, backward or sideways) or collapse.
    Fall,
    /// Breathing and looking around.
    Idle,
    /// Wings flapping while travelling through the air.
    Fly,
    /// A travelling wave along a snake's body.
    Slither,
}

impl Action {
    pub const ALL: [Action; 10] = [
        Action::Walk,
        Action::Run,
        Action::Jump,
        Action::Turn,
        Action::Attack,
        Action::Wave,
        Action::Fall,
        Action::Idle,
        Action::Fly,
        Action::Slither,
    ];

    /// Name used in clip ids.
    pub fn name(self) -> &'static str {
        match self {
            Action::Walk => "walk",
            Action::Run => "run",
            Action::Jump => "jump",
            Action::Turn => "turn",
            Action::Attack => "attack",
            Action::Wave => "wave",
            Action::Fall => "fall",
            Action::Idle => "idle",
            Action::Fly => "fly",
            Action::Slither => "slither",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|a| a.name() == name)
    }
}

/// The drawn parameters of one action.
#[derive(Debug, Clone)]
pub(super) struct Motion {
    pub action: Action,
    /// Cycles (steps, flaps, waves, breaths) over the clip.
    pub cycles: f32,
    /// Speed relative to the action's usual pace (0.7–1.4): "slowly" below 0.85, "quickly" above 1.2.
    pub pace: f32,
    /// Amplitude relative to the action's usual one (0.7–1.4): "gently" below 0.85, "wildly" above 1.2.
    pub amp: f32,
    /// Which side acts or which way it turns or falls: +1 right, −1 left.
    pub side: f32,
    /// Turn angle (degrees), fall direction (0 forward, 1 backward, 2 sideways), jump or flight height (metres).
    pub extent: f32,
    /// Travel distance along the facing direction (metres).
    pub travel: f32,
    /// When a fall starts (τ).
    pub onset: f32,
}

pub(super) fn draw(action: Action, rig: &Rig, r: &mut DataRng) -> Motion {
    let pace = r.random_range(0.7f32..1.4);
    let amp = r.random_range(0.7f32..1.4);
    let side = if r.random_bool(0.5) { 1.0 } else { -1.0 };
    let size = rig.leg.max(0.2 * rig.length);
    let (cycles, extent, travel) = match action {
        Action::Walk => {
            let c = pace * r.random_range(0.9f32..1.6);
            (c, 0.0, c * 2.0 * size * (0.45 * amp).sin())
        }
        Action::Run => {
            let c = pace * r.random_range(1.0f32..1.6);
            (c, 0.0, c * 2.6 * size * (0.6 * amp).sin())
        }
        Action::Jump => {
            let forward = r.random_bool(0.5);
            (
                1.0,
                r.random_range(0.2f32..0.5) * size * amp,
                if forward {
                    r.random_range(0.4f32..1.0) * size
                } else {
                    0.0
                },
            )
        }
        Action::Turn => (pace * r.random_range(0.8f32..1.5), r.random_range(60.0f32..180.0), 0.0),
        Action::Attack => (1.0, 0.0, 0.0),
        Action::Wave => (pace * r.random_range(1.5f32..3.0), 0.0, 0.0),
        Action::Fall => (1.0, r.random_range(0..3) as f32, 0.0),
        Action::Idle => (pace * r.random_range(0.8f32..1.8), 0.0, 0.0),
        Action::Fly => {
            let c = pace * r.random_range(2.0f32..4.0);
            (
                c,
                r.random_range(0.5f32..1.5) * rig.length,
                r.random_range(1.0f32..3.0) * rig.length * pace,
            )
        }
        Action::Slither => {
            let c = pace * r.random_range(0.8f32..1.6);
            (c, 0.0, c * r.random_range(0.25f32..0.4) * rig.length)
        }
    };
    Motion {
        action,
        cycles,
        pace,
        amp,
        side,
        extent,
        travel,
        onset: r.random_range(0.0f32..0.3),
    }
}

/// Unit quaternion `(x, y, z, w)` of a rotation by `deg` degrees about canonical axis `axis`.
fn q(axis: usize, deg: f32) -> [f64; 4] {
    let h = f64::from(deg).to_radians() / 2.0;
    let mut out = [0.0, 0.0, 0.0, h.cos()];
    out[axis] = h.sin();
    out
}

/// `a` then `b` applied after it: `b · a`.
fn then(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    crate::formats::skeletal::quat_mul(b, a)
}

fn smooth(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// 0 outside `[a, b]`, rising to 1 and back as a half sine inside.
fn bump(t: f32, a: f32, b: f32) -> f32 {
    if t <= a || t >= b {
        0.0
    } else {
        (PI * (t - a) / (b - a)).sin()
    }
}

fn set(p: &mut Pose, bone: Option<&usize>, rot: [f64; 4]) {
    if let Some(&b) = bone {
        p.rot[b] = then(p.rot[b], rot);
    }
}

/// A gait at phase `cycles · τ`: hips (or, for sprawling insect legs, protraction and lift), knees, arms against
/// the legs, tail and chest counter-swinging.
fn gait(p: &mut Pose, rig: &Rig, cycles: f32, tau: f32, hip: f32, knee: f32) {
    for leg in &rig.legs {
        let phi = TAU * (cycles * tau + leg.phase);
        if rig.template == Template::Insect {
            let lift = -leg.side * 0.6 * hip * phi.cos().max(0.0);
            set(p, leg.bones.first(), then(q(0, lift), q(1, leg.side * hip * phi.sin())));
        } else {
            let swing = hip * phi.sin();
            let bend = -knee * phi.cos().max(0.0);
            set(p, leg.bones.first(), q(2, swing));
            set(p, leg.bones.get(1), q(2, bend));
            set(p, leg.bones.get(2), q(2, -0.5 * (swing + bend)));
        }
    }
    let left = TAU * cycles * tau;
    for arm in rig.arms.iter().filter(|_| rig.template != Template::Insect) {
        let phi = TAU * (cycles * tau + arm.phase);
        set(p, arm.bones.first(), q(2, 0.7 * hip * phi.sin()));
        set(p, arm.bones.get(1), q(2, 15.0 + 0.3 * hip * (1.0 + phi.sin())));
    }
    set(p, rig.spine.last(), q(1, 0.15 * hip * left.sin()));
    for (k, b) in rig.tail.iter().enumerate() {
        p.rot[*b] = then(p.rot[*b], q(1, 0.3 * hip * (left - 0.6 * k as f32).sin()));
    }
    set(p, rig.neck.first(), q(2, 0.1 * hip * (2.0 * left).sin()));
}

/// A snake's body as a travelling wave: segment k heads `deg · sin 2π(phase − 1.2 k / n)` from the body's axis
/// (the head is segment 0), each joint turning by the difference to the segment before it.
fn serpentine(p: &mut Pose, rig: &Rig, deg: f32, phase: f32) {
    let n = rig.body.len().max(1) as f32;
    let heading = |k: usize| deg * (TAU * (phase - 1.2 * k as f32 / n)).sin();
    set(p, rig.head.as_ref(), q(1, heading(0)));
    for (k, seg) in rig.body.iter().enumerate() {
        p.rot[*seg] = then(p.rot[*seg], q(1, heading(k + 1) - heading(k)));
    }
}

/// Lift a sideways limb (insect leg, wing) by `deg`, or swing a hanging one (arm) outwards.
fn abduct(p: &mut Pose, limb: &Chain, deg: f32) {
    set(p, limb.bones.first(), q(0, -limb.side * deg));
}

/// The posture at clip time τ.
pub(super) fn pose(m: &Motion, rig: &Rig, tau: f32) -> Pose {
    let mut p = Pose::rest(rig.bones.len());
    // Birds fold their wings along the body unless flying.
    if rig.template == Template::Bird && m.action != Action::Fly {
        for w in &rig.wings {
            set(&mut p, w.bones.first(), q(1, -w.side * 75.0));
            set(&mut p, w.bones.get(1), q(1, -w.side * 60.0));
        }
    }
    let root = rig.bones[0].head;
    let a = m.amp;
    match m.action {
        Action::Walk => {
            gait(&mut p, rig, m.cycles, tau, 25.0 * a, 35.0 * a);
            p.shift[0] = m.travel * tau;
        }
        Action::Run => {
            gait(&mut p, rig, m.cycles, tau, 35.0 * a, 60.0 * a);
            set(&mut p, rig.spine.get(1), q(2, -12.0 * a));
            for arm in &rig.arms {
                set(&mut p, arm.bones.get(1), q(2, 40.0));
            }
            p.shift[0] = m.travel * tau;
            p.ground = Some(0.08 * rig.leg * a * (TAU * 2.0 * m.cycles * tau).sin().max(0.0));
        }
        Action::Jump => {
            let crouch = bump(tau, 0.0, 0.35) + 0.5 * bump(tau, 0.8, 1.0);
            let u = ((tau - 0.3) / 0.55).clamp(0.0, 1.0);
            let air = 4.0 * u * (1.0 - u);
            for leg in &rig.legs {
                set(&mut p, leg.bones.first(), q(2, 35.0 * crouch + 20.0 * air));
                set(&mut p, leg.bones.get(1), q(2, -70.0 * crouch - 30.0 * air));
                set(&mut p, leg.bones.get(2), q(2, 35.0 * crouch + 10.0 * air));
            }
            for arm in &rig.arms {
                set(
                    &mut p,
                    arm.bones.first(),
                    q(2, -30.0 * crouch + 90.0 * a.min(1.0) * air),
                );
            }
            set(&mut p, rig.spine.get(1), q(2, -20.0 * crouch));
            set(&mut p, rig.neck.first(), q(2, 15.0 * crouch));
            p.shift[0] = m.travel * smooth(u);
            p.ground = Some(m.extent * air);
        }
        Action::Turn => {
            gait(&mut p, rig, m.cycles, tau, 12.0 * a, 25.0 * a);
            if rig.template == Template::Snake {
                for b in &rig.body {
                    p.rot[*b] = then(
                        p.rot[*b],
                        q(
                            1,
                            -m.side * 0.6 * m.extent / rig.body.len() as f32 * bump(tau, 0.0, 1.0),
                        ),
                    );
                }
            }
            p.body = q(1, -m.side * m.extent * smooth(tau));
            p.pivot = [root[0], 0.0, root[2]];
        }
        Action::Attack => attack(&mut p, m, rig, tau),
        Action::Wave => wave(&mut p, m, rig, tau),
        Action::Fall => fall(&mut p, m, rig, tau),
        Action::Idle => {
            let b = (TAU * m.cycles * tau).sin();
            for s in &rig.spine {
                p.scale[*s] = 1.0 + f64::from(0.025 * a * b);
            }
            set(
                &mut p,
                rig.neck.first(),
                q(1, 25.0 * a * (PI * m.cycles * tau + m.side).sin()),
            );
            set(
                &mut p,
                rig.head.filter(|_| rig.neck.is_empty()).as_ref(),
                q(1, 8.0 * a * (TAU * tau).sin()),
            );
            for arm in &rig.arms {
                set(&mut p, arm.bones.first(), q(2, 4.0 * a * b));
            }
            if !rig.body.is_empty() {
                serpentine(&mut p, rig, 8.0 * a, 0.5 * m.cycles * tau);
            }
            for (k, t) in rig.tail.iter().enumerate() {
                p.rot[*t] = then(p.rot[*t], q(2, 6.0 * a * (TAU * m.cycles * tau - k as f32).sin()));
            }
        }
        Action::Fly => {
            let phi = TAU * m.cycles * tau;
            for w in &rig.wings {
                abduct(&mut p, w, 45.0 * a * phi.sin());
                set(&mut p, w.bones.get(1), q(0, -w.side * 25.0 * a * (phi - 0.8).sin()));
            }
            for leg in &rig.legs {
                set(&mut p, leg.bones.first(), q(2, -60.0));
                set(&mut p, leg.bones.get(1), q(2, 50.0));
            }
            set(&mut p, rig.spine.first(), q(2, -8.0 + 4.0 * phi.cos()));
            p.shift[0] = m.travel * tau;
            p.ground = Some(m.extent * (0.3 + 0.7 * tau) + 0.04 * rig.length * a * phi.cos());
        }
        Action::Slither => {
            serpentine(&mut p, rig, 30.0 * a, m.cycles * tau);
            p.shift[0] = m.travel * tau;
        }
    }
    p
}

fn attack(p: &mut Pose, m: &Motion, rig: &Rig, tau: f32) {
    let wind = smooth(tau / 0.35) * (1.0 - smooth((tau - 0.33) / 0.2));
    let strike = smooth((tau - 0.33) / 0.3) * (1.0 - smooth((tau - 0.7) / 0.3));
    let a = m.amp.min(1.2);
    match rig.template {
        Template::Biped | Template::MultiArm => {
            for arm in rig.arms.iter().filter(|c| c.side == m.side) {
                set(p, arm.bones.first(), q(2, -60.0 * a * wind + 90.0 * a * strike));
                abduct(p, arm, 20.0 * wind);
                set(p, arm.bones.get(1), q(2, 70.0 * wind + 10.0 * strike));
            }
            set(p, rig.spine.get(1), q(1, m.side * (25.0 * wind - 30.0 * strike)));
            let step = rig.legs.iter().find(|l| l.side == -m.side);
            if let Some(leg) = step {
                set(p, leg.bones.first(), q(2, 25.0 * strike));
                set(p, leg.bones.get(1), q(2, -20.0 * strike));
            }
            p.shift[0] = 0.15 * rig.leg * smooth((tau - 0.3) / 0.3);
        }
        Template::Quadruped => {
            set(p, rig.neck.first(), q(2, 25.0 * wind - 50.0 * a * strike));
            set(p, rig.head.as_ref(), q(2, -20.0 * strike));
            for leg in rig.legs.iter().take(2) {
                set(p, leg.bones.first(), q(2, -15.0 * wind + 25.0 * strike));
            }
            p.body = q(2, 8.0 * wind - 6.0 * strike);
            p.pivot = rig.bones[0].head;
            p.shift[0] = 0.25 * rig.length * a * strike;
        }
        Template::Insect => {
            for leg in rig.legs.iter().take(2) {
                abduct(p, leg, 50.0 * a * wind + 10.0 * strike);
                set(p, leg.bones.first(), q(1, leg.side * 40.0 * strike));
            }
            for ant in &rig.arms {
                abduct(p, ant, 30.0 * wind);
            }
            p.shift[0] = 0.2 * rig.length * strike;
        }
        Template::Bird => {
            let pecks = (2.0 * m.pace).round().max(1.0);
            let peck = (TAU * pecks * tau).sin().max(0.0);
            set(p, rig.neck.first(), q(2, -60.0 * a * peck));
            set(p, rig.head.as_ref(), q(2, -30.0 * peck));
        }
        Template::Snake => {
            // Rear up: the head and the first two segments tilt up, the rest lies flat; an S-coil behind them,
            // then the lunge.
            let rear = 45.0 * wind + 15.0 * strike;
            set(p, rig.head.as_ref(), q(2, rear));
            set(p, rig.body.get(1), q(2, -rear));
            for (k, seg) in rig.body.iter().enumerate().skip(2).take(4) {
                let coil = if k % 2 == 0 { 1.0 } else { -1.0 };
                p.rot[*seg] = then(p.rot[*seg], q(1, coil * 35.0 * wind));
            }
            p.shift[0] = 0.25 * rig.length * a * strike;
        }
    }
}

fn wave(p: &mut Pose, m: &Motion, rig: &Rig, tau: f32) {
    let up = smooth(tau / 0.3);
    let phi = TAU * m.cycles * tau;
    let a = m.amp;
    match rig.template {
        Template::Biped | Template::MultiArm => {
            if let Some(arm) = rig.arms.iter().find(|c| c.side == m.side) {
                abduct(p, arm, 140.0 * up);
                set(
                    p,
                    arm.bones.get(1),
                    q(0, -arm.side * (20.0 + 25.0 * a * phi.sin()) * up),
                );
            }
            set(p, rig.neck.first(), q(0, -m.side * 8.0 * up));
        }
        Template::Quadruped => {
            for (k, t) in rig.tail.iter().enumerate() {
                p.rot[*t] = then(p.rot[*t], q(1, 30.0 * a * up * (phi - 0.7 * k as f32).sin()));
            }
            set(p, rig.neck.first(), q(0, 10.0 * up * (0.5 * phi).sin()));
        }
        Template::Insect => {
            for ant in &rig.arms {
                abduct(p, ant, 35.0 * a * (phi + ant.side).sin());
                set(p, ant.bones.first(), q(1, ant.side * 20.0 * a * (0.5 * phi).sin()));
            }
            if let Some(leg) = rig.legs.iter().find(|l| l.side == m.side) {
                abduct(p, leg, 45.0 * up + 15.0 * a * phi.sin() * up);
            }
        }
        Template::Bird => {
            for w in &rig.wings {
                // Unfold then flap in place.
                set(p, w.bones.first(), q(1, w.side * 75.0 * up));
                set(p, w.bones.get(1), q(1, w.side * 60.0 * up));
                abduct(p, w, 40.0 * a * up * phi.sin());
            }
        }
        Template::Snake => {
            set(p, rig.head.as_ref(), q(1, 20.0 * a * phi.sin()));
        }
    }
}

fn fall(p: &mut Pose, m: &Motion, rig: &Rig, tau: f32) {
    let x = ((tau - m.onset) / 0.55).clamp(0.0, 1.0);
    let down = x * x;
    let settle = 0.04 * bump(tau, m.onset + 0.55, 1.0);
    match rig.template {
        Template::Insect => {
            for leg in &rig.legs {
                abduct(p, leg, 70.0 * down);
                set(p, leg.bones.get(1), q(0, -leg.side * 60.0 * down));
            }
            for ant in &rig.arms {
                abduct(p, ant, -20.0 * down);
            }
        }
        _ => {
            let (axis, angle) = match (rig.template, m.extent as u32) {
                (Template::Quadruped, _) | (_, 2) => (0, -m.side * 88.0),
                (_, 0) => (2, -85.0),
                _ => (2, 85.0),
            };
            p.body = q(axis, angle * (down - settle));
            p.pivot = [rig.bones[0].head[0], 0.0, 0.0];
            for leg in &rig.legs {
                set(p, leg.bones.get(1), q(2, -40.0 * down));
                set(p, leg.bones.first(), q(2, 20.0 * down));
            }
            for arm in &rig.arms {
                abduct(p, arm, 60.0 * bump(x, 0.0, 1.0) * m.amp);
            }
            set(p, rig.neck.first(), q(2, 25.0 * down));
        }
    }
}
