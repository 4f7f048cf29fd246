//! The six skeleton templates, each with random proportions, optional extra limbs and the skin parts around its
//! bones. Canonical frame: facing +x, y up, right side towards +z, feet on y = 0.

use super::{Action, Chain, Rig};
use crate::rng::{DataRng, Rng};
use crate::synth::V3;

/// Which skeleton a rigged character has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Template {
    /// Two legs, two arms, spine, neck and head; sometimes a tail.
    Biped,
    /// Four legs, a horizontal trunk, neck, head and tail.
    Quadruped,
    /// Thorax, abdomen, head with antennae and six or eight jointed legs.
    Insect,
    /// Round body, neck, head with a beak, two wings, two legs and a tail.
    Bird,
    /// A long body of 8 to 14 segments behind a head.
    Snake,
    /// A biped with two or four extra arms.
    MultiArm,
}

impl Template {
    pub const ALL: [Template; 6] = [
        Template::Biped,
        Template::Quadruped,
        Template::Insect,
        Template::Bird,
        Template::Snake,
        Template::MultiArm,
    ];

    /// Name used in clip ids.
    pub fn name(self) -> &'static str {
        match self {
            Template::Biped => "biped",
            Template::Quadruped => "quadruped",
            Template::Insect => "insect",
            Template::Bird => "bird",
            Template::Snake => "snake",
            Template::MultiArm => "multiarm",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The actions this skeleton can perform.
    pub fn actions(self) -> &'static [Action] {
        use Action::*;
        match self {
            Template::Biped | Template::MultiArm => &[Walk, Run, Jump, Turn, Attack, Wave, Fall, Idle],
            Template::Quadruped => &[Walk, Run, Jump, Turn, Attack, Wave, Fall, Idle],
            Template::Insect => &[Walk, Run, Turn, Attack, Wave, Fall, Idle],
            Template::Bird => &[Walk, Fly, Turn, Attack, Wave, Fall, Idle],
            Template::Snake => &[Slither, Turn, Attack, Idle],
        }
    }
}

/// One of `words`, uniformly.
fn pick<'a>(r: &mut DataRng, words: &[&'a str]) -> &'a str {
    words[r.random_range(0..words.len())]
}

/// `word` when `x` is outside `[lo, hi]` on its side, else nothing.
fn grade(x: f32, lo: f32, hi: f32, low: &'static str, high: &'static str) -> Option<String> {
    if x < lo {
        Some(low.into())
    } else if x > hi {
        Some(high.into())
    } else {
        None
    }
}

pub(super) fn build(template: Template, r: &mut DataRng) -> Rig {
    let mut rig = Rig::new(template);
    match template {
        Template::Biped => humanoid(&mut rig, 0, r),
        Template::MultiArm => {
            let extra = r.random_range(1..=2);
            humanoid(&mut rig, extra, r);
        }
        Template::Quadruped => quadruped(&mut rig, r),
        Template::Insect => insect(&mut rig, r),
        Template::Bird => bird(&mut rig, r),
        Template::Snake => snake(&mut rig, r),
    }
    rig
}

/// A biped with `extra` more pairs of arms below the first.
fn humanoid(rig: &mut Rig, extra: usize, r: &mut DataRng) {
    let h = r.random_range(1.4f32..2.0);
    let w = r.random_range(0.75f32..1.3);
    let leg_f = r.random_range(0.42f32..0.55);
    let arm_f = r.random_range(0.85f32..1.15);
    let hip = leg_f * h;
    let chest = hip + 0.3 * h;
    let pelvis = rig.bone(None, [0.0, hip, 0.0], [0.0, hip + 0.1 * h, 0.0]);
    let spine = rig.bone(Some(pelvis), [0.0, hip + 0.1 * h, 0.0], [0.0, chest, 0.0]);
    rig.spine = vec![pelvis, spine];
    let neck = rig.bone(Some(spine), [0.0, chest, 0.0], [0.01 * h, chest + 0.05 * h, 0.0]);
    let head_r = 0.06 * h * r.random_range(0.85f32..1.2);
    let head = rig.bone(
        Some(neck),
        [0.01 * h, chest + 0.05 * h, 0.0],
        [0.02 * h, chest + 0.05 * h + 1.6 * head_r, 0.0],
    );
    rig.neck = vec![neck];
    rig.head = Some(head);
    let torso_r = 0.11 * h * w;
    rig.part(
        [0.0, hip, 0.0],
        [0.0, chest - 0.02 * h, 0.0],
        (torso_r, torso_r * 1.1),
        &[pelvis, spine],
    );
    rig.part(
        [0.0, chest - 0.02 * h, 0.0],
        [0.01 * h, chest + 0.06 * h, 0.0],
        (0.045 * h * w, 0.04 * h),
        &[neck],
    );
    rig.part(
        [0.015 * h, chest + 0.05 * h + head_r * 0.8, 0.0],
        [0.02 * h, chest + 0.05 * h + head_r * 1.0, 0.0],
        (head_r, head_r),
        &[head],
    );
    for pair in 0..=extra {
        let k = pair as f32;
        let y = chest - 0.04 * h - 0.09 * h * k;
        let len = 0.33 * h * arm_f * (1.0 - 0.1 * k);
        let ar = 0.033 * h * w * (1.0 - 0.15 * k);
        for side in [1.0f32, -1.0] {
            let z = side * (torso_r * 1.05 + ar);
            let pts = [
                [0.0, y, z],
                [0.0, y - 0.52 * len, z + side * 0.02 * h],
                [0.01 * h, y - len, z + side * 0.03 * h],
                [0.02 * h, y - len - 0.08 * h, z + side * 0.03 * h],
            ];
            let bones = rig.chain(spine, &pts);
            rig.part(pts[0], pts[2], (ar, ar * 0.8), &bones[..2]);
            rig.part(pts[2], pts[3], (ar * 0.8, ar * 0.7), &bones[2..]);
            rig.arms.push(Chain {
                bones,
                side,
                phase: if side > 0.0 { 0.5 } else { 0.0 },
            });
        }
    }
    let lr = 0.055 * h * w;
    for side in [1.0f32, -1.0] {
        let z = side * 0.09 * h * w;
        let ankle = 0.06 * hip;
        let pts = [
            [0.0, hip, z],
            [0.01 * h, hip * 0.52, z],
            [0.0, ankle, z],
            [0.13 * h, lr * 0.4, z],
        ];
        let bones = rig.chain(pelvis, &pts);
        rig.part(pts[0], pts[2], (lr, lr * 0.65), &bones[..2]);
        rig.part(pts[2], pts[3], (lr * 0.6, lr * 0.45), &bones[2..]);
        rig.legs.push(Chain {
            bones,
            side,
            phase: if side > 0.0 { 0.0 } else { 0.5 },
        });
    }
    if extra == 0 && r.random_bool(0.3) {
        let tl = r.random_range(0.4f32..0.8) * h;
        let pts = [
            [-0.08 * h, hip + 0.02 * h, 0.0],
            [-0.08 * h - 0.45 * tl, hip - 0.15 * tl, 0.0],
            [-0.08 * h - 0.85 * tl, hip - 0.2 * tl, 0.0],
            [-0.08 * h - tl, hip - 0.1 * tl, 0.0],
        ];
        rig.tail = rig.chain(pelvis, &pts);
        let tail = rig.tail.clone();
        rig.part(pts[0], pts[3], (0.035 * h * w, 0.01 * h), &tail);
    }
    rig.leg = hip;
    rig.length = 0.3 * h;
    rig.words.extend(grade(h, 1.6, 1.8, "short", "tall"));
    rig.words.extend(grade(w, 0.9, 1.15, "thin", "stocky"));
    if leg_f > 0.52 {
        rig.words.push("long-legged".into());
    }
    let noun = match extra {
        0 if !rig.tail.is_empty() => "humanoid with a tail".to_string(),
        0 => pick(r, &["humanoid", "character", "figure"]).to_string(),
        1 => format!("four-armed {}", pick(r, &["figure", "creature", "humanoid"])),
        _ => format!("six-armed {}", pick(r, &["figure", "creature", "humanoid"])),
    };
    rig.words.push(noun);
}

fn quadruped(rig: &mut Rig, r: &mut DataRng) {
    let len = r.random_range(0.8f32..1.6);
    let leg_f = r.random_range(0.35f32..0.8);
    let girth = r.random_range(0.8f32..1.25);
    let leg = leg_f * len * 0.8;
    let br = 0.15 * len * girth;
    let y = leg + 0.5 * br;
    let back = rig.bone(None, [-0.45 * len, y, 0.0], [0.0, y, 0.0]);
    let front = rig.bone(Some(back), [0.0, y, 0.0], [0.45 * len, y + 0.02 * len, 0.0]);
    rig.spine = vec![back, front];
    rig.part(
        [-0.42 * len, y, 0.0],
        [0.42 * len, y + 0.02 * len, 0.0],
        (br, br * 1.05),
        &[back, front],
    );
    let neck_len = r.random_range(0.25f32..0.45) * len;
    let nk = [0.45 * len + 0.5 * neck_len, y + 0.8 * neck_len, 0.0];
    let neck = rig.bone(Some(front), [0.45 * len, y + 0.02 * len, 0.0], nk);
    let hr = 0.1 * len * r.random_range(0.8f32..1.2);
    let snout = [nk[0] + 2.2 * hr, nk[1] - 0.4 * hr, 0.0];
    let head = rig.bone(Some(neck), nk, snout);
    rig.neck = vec![neck];
    rig.head = Some(head);
    rig.part([0.4 * len, y, 0.0], nk, (0.07 * len * girth, 0.055 * len), &[neck]);
    rig.part(
        [nk[0] + 0.4 * hr, nk[1], 0.0],
        [snout[0] - 0.5 * hr, snout[1], 0.0],
        (hr, hr * 0.6),
        &[head],
    );
    let tl = r.random_range(0.2f32..0.7) * len;
    let t0 = [-0.45 * len, y + 0.05 * len, 0.0];
    let pts = [
        t0,
        [t0[0] - 0.35 * tl, t0[1] + 0.1 * tl, 0.0],
        [t0[0] - 0.7 * tl, t0[1] + 0.05 * tl, 0.0],
        [t0[0] - tl, t0[1] - 0.1 * tl, 0.0],
    ];
    rig.tail = rig.chain(back, &pts);
    let tail = rig.tail.clone();
    rig.part(pts[0], pts[3], (0.03 * len * girth, 0.012 * len), &tail);
    let lr = 0.055 * len * girth;
    // Walk: left hind, left fore, right hind, right fore a quarter cycle apart.
    for (x, side, phase) in [
        (0.33, 1.0f32, 0.75),
        (0.33, -1.0, 0.25),
        (-0.33, 1.0, 0.5),
        (-0.33, -1.0, 0.0),
    ] {
        let (x, z) = (x * len, side * 0.6 * br);
        let knee = if x > 0.0 { 0.02 * len } else { -0.04 * len };
        let pts = [
            [x, leg + 0.2 * br, z],
            [x + knee, 0.5 * leg, z],
            [x, 0.05 * leg, z],
            [x + 0.06 * len, lr * 0.4, z],
        ];
        let bones = rig.chain(if x > 0.0 { front } else { back }, &pts);
        rig.part(pts[0], pts[2], (lr, lr * 0.65), &bones[..2]);
        rig.part(pts[2], pts[3], (lr * 0.6, lr * 0.5), &bones[2..]);
        rig.legs.push(Chain { bones, side, phase });
    }
    rig.leg = leg;
    rig.length = len;
    rig.words.extend(grade(len, 1.0, 1.4, "small", "large"));
    rig.words.extend(grade(leg_f, 0.45, 0.7, "short-legged", "long-legged"));
    rig.words
        .push(pick(r, &["four-legged animal", "quadruped", "four-legged creature"]).into());
}

fn insect(rig: &mut Rig, r: &mut DataRng) {
    let len = r.random_range(0.5f32..1.2);
    let pairs = if r.random_bool(0.35) { 4 } else { 3 };
    let hb = r.random_range(0.15f32..0.3) * len;
    let thorax = rig.bone(None, [-0.15 * len, hb, 0.0], [0.15 * len, hb, 0.0]);
    rig.spine = vec![thorax];
    rig.part(
        [-0.12 * len, hb, 0.0],
        [0.12 * len, hb, 0.0],
        (0.1 * len, 0.09 * len),
        &[thorax],
    );
    let ab_len = r.random_range(0.3f32..0.6) * len;
    let abdomen = rig.bone(
        Some(thorax),
        [-0.15 * len, hb, 0.0],
        [-0.15 * len - ab_len, hb + 0.05 * len, 0.0],
    );
    rig.tail = vec![abdomen];
    let ar = 0.13 * len * r.random_range(0.8f32..1.3);
    rig.part(
        [-0.15 * len - 0.3 * ab_len, hb + 0.01 * len, 0.0],
        [-0.15 * len - 0.85 * ab_len, hb + 0.04 * len, 0.0],
        (ar, ar * 0.7),
        &[abdomen],
    );
    let head = rig.bone(Some(thorax), [0.15 * len, hb, 0.0], [0.3 * len, hb + 0.02 * len, 0.0]);
    rig.head = Some(head);
    rig.part(
        [0.2 * len, hb, 0.0],
        [0.26 * len, hb + 0.02 * len, 0.0],
        (0.07 * len, 0.06 * len),
        &[head],
    );
    for side in [1.0f32, -1.0] {
        let z = side * 0.03 * len;
        let pts = [
            [0.3 * len, hb + 0.04 * len, z],
            [0.4 * len, hb + 0.18 * len, z + side * 0.08 * len],
            [0.55 * len, hb + 0.22 * len, z + side * 0.14 * len],
        ];
        let bones = rig.chain(head, &pts);
        rig.skin_each(&bones, 0.012 * len, 0.007 * len);
        rig.arms.push(Chain {
            bones,
            side,
            phase: 0.0,
        });
    }
    let reach = r.random_range(0.45f32..0.8) * len;
    let lr = 0.025 * len;
    for k in 0..pairs {
        let x = 0.12 * len - 0.24 * len * k as f32 / (pairs - 1) as f32;
        let splay = 0.25 * len * (k as f32 / (pairs - 1) as f32 - 0.5);
        for side in [1.0f32, -1.0] {
            let z = side * 0.07 * len;
            let pts = [
                [x, hb, z],
                [x - 0.3 * splay, hb + 0.12 * len, side * 0.5 * reach],
                [x - splay, lr * 0.5, side * reach],
            ];
            let bones = rig.chain(thorax, &pts);
            rig.skin_each(&bones, lr, lr * 0.5);
            // Alternating tripods: a leg and its diagonal neighbours step together.
            let phase = if (k % 2 == 0) == (side > 0.0) { 0.0 } else { 0.5 };
            rig.legs.push(Chain { bones, side, phase });
        }
    }
    rig.leg = hb;
    rig.length = len;
    rig.words.extend(grade(len, 0.7, 1.0, "small", "large"));
    if reach > 0.7 * len {
        rig.words.push("long-legged".into());
    }
    rig.words.push(if pairs == 4 {
        pick(r, &["eight-legged spider", "eight-legged creature"]).into()
    } else {
        pick(r, &["six-legged insect", "six-legged creature", "beetle"]).into()
    });
}

fn bird(rig: &mut Rig, r: &mut DataRng) {
    let len = r.random_range(0.3f32..0.9);
    let leg_f = r.random_range(0.4f32..1.0);
    let leg = leg_f * len * 0.6;
    let br = 0.2 * len;
    let y = leg + 0.7 * br;
    let body = rig.bone(None, [-0.2 * len, y, 0.0], [0.2 * len, y + 0.08 * len, 0.0]);
    rig.spine = vec![body];
    rig.part(
        [-0.15 * len, y, 0.0],
        [0.15 * len, y + 0.06 * len, 0.0],
        (br, br * 0.85),
        &[body],
    );
    let nk = [0.32 * len, y + 0.35 * len * r.random_range(0.6f32..1.2), 0.0];
    let neck = rig.bone(Some(body), [0.2 * len, y + 0.08 * len, 0.0], nk);
    let hr = 0.1 * len;
    let head = rig.bone(Some(neck), nk, [nk[0] + 0.3 * len, nk[1] - 0.02 * len, 0.0]);
    rig.neck = vec![neck];
    rig.head = Some(head);
    rig.part([0.2 * len, y + 0.06 * len, 0.0], nk, (0.07 * len, 0.05 * len), &[neck]);
    rig.part(
        [nk[0] + 0.02 * len, nk[1], 0.0],
        [nk[0] + 0.05 * len, nk[1], 0.0],
        (hr, hr),
        &[head],
    );
    rig.part(
        [nk[0] + 0.12 * len, nk[1] - 0.01 * len, 0.0],
        [nk[0] + 0.3 * len, nk[1] - 0.02 * len, 0.0],
        (0.035 * len, 0.006 * len),
        &[head],
    );
    let tail = rig.bone(Some(body), [-0.2 * len, y, 0.0], [-0.55 * len, y + 0.05 * len, 0.0]);
    rig.tail = vec![tail];
    rig.part(
        [-0.25 * len, y, 0.0],
        [-0.5 * len, y + 0.05 * len, 0.0],
        (0.06 * len, 0.02 * len),
        &[tail],
    );
    let span = r.random_range(0.8f32..1.6) * len;
    for side in [1.0f32, -1.0] {
        let z = side * 0.7 * br;
        let pts = [
            [0.05 * len, y + 0.1 * len, z],
            [0.0, y + 0.12 * len, side * (0.7 * br + 0.45 * span)],
            [-0.1 * len, y + 0.1 * len, side * (0.7 * br + span)],
        ];
        let bones = rig.chain(body, &pts);
        rig.skin_each(&bones, 0.06 * len, 0.015 * len);
        rig.wings.push(Chain {
            bones,
            side,
            phase: 0.0,
        });
    }
    let lr = 0.03 * len;
    for side in [1.0f32, -1.0] {
        let z = side * 0.35 * br;
        let pts = [
            [0.0, y - 0.5 * br, z],
            [0.04 * len, 0.5 * leg, z],
            [0.0, 0.05 * leg, z],
            [0.12 * len, lr * 0.4, z],
        ];
        let bones = rig.chain(body, &pts);
        rig.skin_each(&bones, lr, lr * 0.6);
        rig.legs.push(Chain {
            bones,
            side,
            phase: if side > 0.0 { 0.0 } else { 0.5 },
        });
    }
    rig.leg = leg;
    rig.length = len;
    rig.words.extend(grade(len, 0.45, 0.75, "small", "large"));
    if leg_f > 0.8 {
        rig.words.push("long-legged".into());
    }
    rig.words.push(pick(r, &["bird", "winged creature"]).into());
}

fn snake(rig: &mut Rig, r: &mut DataRng) {
    let len = r.random_range(1.5f32..3.0);
    let rad = r.random_range(0.025f32..0.05) * len;
    let segs = r.random_range(8..=14);
    let hl = 2.5 * rad;
    let x0 = 0.5 * len - hl;
    let head = rig.bone(None, [x0, rad, 0.0], [0.5 * len, rad, 0.0]);
    rig.head = Some(head);
    rig.spine = vec![head];
    rig.part(
        [x0 + 0.6 * rad, rad * 1.05, 0.0],
        [0.5 * len - 0.9 * rad, rad * 1.0, 0.0],
        (1.25 * rad, 0.8 * rad),
        &[head],
    );
    let seg = (len - hl) / segs as f32;
    let pts: Vec<V3> = (0..=segs).map(|k| [x0 - seg * k as f32, rad, 0.0]).collect();
    rig.body = rig.chain(head, &pts);
    let body = rig.body.clone();
    rig.part(
        [x0 + 0.5 * rad, rad, 0.0],
        [-0.5 * len + 0.2 * rad, rad, 0.0],
        (rad, 0.25 * rad),
        &body,
    );
    rig.leg = rad;
    rig.length = len;
    rig.words.extend(grade(len, 2.0, 2.6, "short", "long"));
    rig.words.extend(grade(rad / len, 0.032, 0.043, "slender", "thick"));
    rig.words.push(pick(r, &["snake", "serpent"]).into());
}
