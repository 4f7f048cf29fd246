//! The synthetic motion families: per-frame deformations of a rest body, and the caption words each motion earns
//! from the parameters it actually drew (speed word from the speed, direction word from the direction).

use std::f32::consts::{PI, TAU};

use super::shapes::{Body, Pivot};
use super::{MotionFamily, V3};
use crate::rng::{DataRng, Rng};

/// What the motions need to know about the rest body along its main axis.
pub(super) struct Geometry {
    /// Rest bounding-box centre.
    center: V3,
    /// Largest rest extent, and largest extent across the main axis.
    size: f32,
    width: f32,
    /// Range of the main axis.
    lo: f32,
    hi: f32,
    /// Main-axis coordinate where deformation starts, and the length it acts over.
    s0: f32,
    l_eff: f32,
}

impl Geometry {
    pub(super) fn of(body: &Body) -> Self {
        let (lo, hi) = crate::preprocess::bounds(&body.pos);
        let a = body.axis;
        let (s0, l_eff) = match body.pivot {
            Pivot::Base(b) => (b, (hi[a] - b).max(1e-3)),
            Pivot::Center => ((lo[a] + hi[a]) / 2.0, ((hi[a] - lo[a]) / 2.0).max(1e-3)),
        };
        Self {
            center: [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0),
            size: (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f32::max),
            width: (0..3).filter(|&k| k != a).map(|k| hi[k] - lo[k]).fold(0.0, f32::max),
            lo: lo[a],
            hi: hi[a],
            s0,
            l_eff,
        }
    }
}

/// A drawn motion with its parameters. Directions are (world axis, sign); angles in radians; `cycles` is the
/// number of periods over the clip.
#[derive(Debug, Clone)]
pub(super) enum Motion {
    Bend {
        dir: (usize, f32),
        angle: f32,
        cycles: f32,
    },
    Twist {
        angle: f32,
        cycles: f32,
    },
    Wave {
        dir: usize,
        amp: f32,
        waves: f32,
        cycles: f32,
        phase: f32,
    },
    Walk {
        heading: V3,
        swing: f32,
        cycles: f32,
        distance: f32,
    },
    Jump {
        hops: u32,
        height: f32,
        travel: V3,
        squash: f32,
    },
    Squash {
        amount: f32,
        cycles: f32,
    },
    Rigid {
        spin: f32,
        travel: V3,
    },
}

/// Draw the parameters of `family` for `body` and the caption phrase they earn (verb, manner, direction).
pub(super) fn draw(family: MotionFamily, body: &Body, geo: &Geometry, r: &mut DataRng) -> (Motion, String) {
    let a = body.axis;
    // Bends and waves of a sheet stay out of its plane.
    let perp: Vec<usize> = if body.closed {
        (0..3).filter(|&k| k != a).collect()
    } else {
        vec![1]
    };
    let sign = |r: &mut DataRng| if r.random_bool(0.5) { 1.0f32 } else { -1.0 };
    let cardinal = |r: &mut DataRng| {
        let base = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]][r.random_range(0..4usize)];
        let jitter = r.random_range(-0.3f32..0.3);
        let (s, c) = jitter.sin_cos();
        [base[0] * c + base[2] * s, 0.0, -base[0] * s + base[2] * c]
    };
    let lying = body.pivot == Pivot::Center;
    match family {
        MotionFamily::Bend => {
            let dir = (perp[r.random_range(0..perp.len())], sign(r));
            // Stubby standing shapes (no longer than wide) need a larger angle to show the bend.
            let stubby = !lying && geo.hi - geo.lo < 1.3 * geo.width;
            let angle = r.random_range(0.8f32..1.8) * if stubby { 1.5 } else { 1.0 };
            let cycles = r.random_range(0.5f32..2.0);
            let verb = if lying { "curling" } else { "bending" };
            (
                Motion::Bend { dir, angle, cycles },
                format!("{verb} {} {}", pace(cycles), axis_word(dir.0, dir.1)),
            )
        }
        MotionFamily::Twist => {
            // Lying shapes twist both ends (in opposite senses), so less at each end.
            let angle = sign(r) * r.random_range(0.8f32..2.4) * if lying { 0.75 } else { 1.0 };
            let cycles = r.random_range(0.5f32..2.0);
            let turn = if angle > 0.0 { "counterclockwise" } else { "clockwise" };
            (
                Motion::Twist { angle, cycles },
                format!("twisting {} {turn}", pace(cycles)),
            )
        }
        MotionFamily::Wave => {
            let dir = perp[r.random_range(0..perp.len())];
            let amp = (geo.hi - geo.lo) * r.random_range(0.08f32..0.2);
            let (waves, cycles, phase) = (
                r.random_range(0.5f32..1.5),
                r.random_range(0.5f32..2.0),
                r.random_range(0.0..TAU),
            );
            let verb = if body.closed { "waving" } else { "rippling" };
            let how = ["from side to side", "up and down", "back and forth"][dir];
            (
                Motion::Wave {
                    dir,
                    amp,
                    waves,
                    cycles,
                    phase,
                },
                format!("{verb} {} {how}", pace(cycles)),
            )
        }
        MotionFamily::Walk => {
            let heading = cardinal(r);
            let legged = !body.limbs.is_empty();
            let run = legged && r.random_bool(0.4);
            let (swing, cycles) = if run {
                (r.random_range(0.5f32..0.7), r.random_range(1.4f32..2.0))
            } else if legged {
                (r.random_range(0.3f32..0.5), r.random_range(0.7f32..1.3))
            } else {
                (0.0, r.random_range(1.0f32..3.0))
            };
            let distance = if legged {
                cycles * 2.0 * body.leg * swing.sin() * 0.8
            } else {
                geo.size * r.random_range(0.3f32..0.6)
            };
            let verb = if run {
                "running"
            } else if legged {
                "walking"
            } else {
                "crawling"
            };
            let speed = distance / geo.size;
            let manner = if run || speed > 0.9 {
                "quickly"
            } else if speed < 0.4 {
                "slowly"
            } else {
                "steadily"
            };
            (
                Motion::Walk {
                    heading,
                    swing,
                    cycles,
                    distance,
                },
                format!("{verb} {manner} {}", vec_word(heading)),
            )
        }
        MotionFamily::Jump => {
            let hops = r.random_range(1u32..=3);
            let height = geo.size * r.random_range(0.2f32..0.45);
            let travel = if r.random_bool(0.4) {
                [0.0; 3]
            } else {
                mul(cardinal(r), geo.size * r.random_range(0.3f32..0.7))
            };
            let squash = r.random_range(0.15f32..0.3);
            let count = ["once", "twice", "three times"][hops as usize - 1];
            let whither = if travel == [0.0; 3] {
                "in place"
            } else {
                vec_word(travel)
            };
            (
                Motion::Jump {
                    hops,
                    height,
                    travel,
                    squash,
                },
                format!("jumping {count} {whither}"),
            )
        }
        MotionFamily::Squash => {
            let amount = sign(r) * r.random_range(0.2f32..0.4);
            let cycles = r.random_range(0.5f32..2.0);
            let order = if amount > 0.0 {
                "stretching and squashing"
            } else {
                "squashing and stretching"
            };
            (Motion::Squash { amount, cycles }, format!("{order} {}", pace(cycles)))
        }
        MotionFamily::Rigid => {
            let spin = sign(r) * r.random_range(1.0f32..5.0);
            let travel = mul(cardinal(r), geo.size * r.random_range(0.3f32..0.8));
            let manner = if spin.abs() < 2.2 {
                "slowly"
            } else if spin.abs() > 3.8 {
                "quickly"
            } else {
                "steadily"
            };
            let turn = if spin > 0.0 { "counterclockwise" } else { "clockwise" };
            (
                Motion::Rigid { spin, travel },
                format!("spinning {turn} {manner} while sliding {}", vec_word(travel)),
            )
        }
    }
}

/// Speed word from the number of periods over the clip.
fn pace(cycles: f32) -> &'static str {
    if cycles < 0.9 {
        "slowly"
    } else if cycles > 1.5 {
        "quickly"
    } else {
        "steadily"
    }
}

/// Viewer-relative word of a world direction: +x right, +y up, +z toward the viewer (the render's camera).
fn axis_word(k: usize, sign: f32) -> &'static str {
    match (k, sign > 0.0) {
        (0, true) => "to the right",
        (0, false) => "to the left",
        (1, true) => "upward",
        (1, false) => "downward",
        (_, true) => "toward the viewer",
        (_, false) => "away from the viewer",
    }
}

fn vec_word(v: V3) -> &'static str {
    let k = (0..3).max_by(|&i, &j| v[i].abs().total_cmp(&v[j].abs())).unwrap_or(0);
    axis_word(k, v[k])
}

fn mul(v: V3, k: f32) -> V3 {
    v.map(|c| c * k)
}

/// Smooth 0 → 1 ramp with zero speed at both ends.
fn ease(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// A 0 → 1 → 0 pulse repeated `cycles` times: (1 − cos 2πcτ) / 2.
fn pulse(cycles: f32, tau: f32) -> f32 {
    (1.0 - (TAU * cycles * tau).cos()) / 2.0
}

/// Rotate `p` about the vertical line through `c` by `psi` (positive = counterclockwise seen from above).
fn yaw(p: V3, c: V3, psi: f32) -> V3 {
    let (s, co) = psi.sin_cos();
    let (x, z) = (p[0] - c[0], p[2] - c[2]);
    [c[0] + x * co + z * s, p[1], c[2] - x * s + z * co]
}

/// Write the pose at flow-free clip time `tau` ∈ [0, 1] into `out` (one row per rest vertex).
pub(super) fn pose(motion: &Motion, body: &Body, geo: &Geometry, tau: f32, out: &mut [V3]) {
    let a = body.axis;
    let c = geo.center;
    out.copy_from_slice(&body.pos);
    // Signed distance from the pivot along the main axis; zero below a base pivot.
    let along = |p: &V3| {
        let s = p[a] - geo.s0;
        if matches!(body.pivot, Pivot::Base(_)) {
            s.max(0.0)
        } else {
            s
        }
    };
    match *motion {
        Motion::Bend { dir, angle, cycles } => {
            let theta = angle * pulse(cycles, tau);
            if theta.abs() > 1e-6 {
                let k = theta / geo.l_eff;
                let (d, sg) = dir;
                for p in out.iter_mut() {
                    let s = along(p);
                    let b = (p[d] - c[d]) * sg;
                    let phi = k * s;
                    let (sin, cos) = phi.sin_cos();
                    p[a] = geo.s0 + sin / k - b * sin + (p[a] - geo.s0 - s);
                    p[d] = c[d] + sg * ((1.0 - cos) / k + b * cos);
                }
            }
        }
        Motion::Twist { angle, cycles } => {
            let alpha = angle * pulse(cycles, tau);
            let (i, j) = ((a + 1) % 3, (a + 2) % 3);
            for p in out.iter_mut() {
                let psi = alpha * along(p) / geo.l_eff;
                let (s, co) = psi.sin_cos();
                let (vi, vj) = (p[i] - c[i], p[j] - c[j]);
                p[i] = c[i] + vi * co - vj * s;
                p[j] = c[j] + vi * s + vj * co;
            }
        }
        Motion::Wave {
            dir,
            amp,
            waves,
            cycles,
            phase,
        } => {
            for p in out.iter_mut() {
                let u = (p[a] - geo.lo) / (geo.hi - geo.lo).max(1e-6);
                let env = match body.pivot {
                    Pivot::Base(_) => along(p) / geo.l_eff,
                    Pivot::Center => 1.0,
                };
                p[dir] += amp * env * (TAU * (waves * u - cycles * tau) + phase).sin();
            }
        }
        Motion::Walk {
            heading,
            swing,
            cycles,
            distance,
        } => {
            let progress = if body.limbs.is_empty() {
                // Crawling: forward in pulses (zero speed between them), contracting at each push.
                stretch(out, body, c, 1.0 - 0.15 * pulse(cycles, tau));
                distance * (tau - (TAU * cycles * tau).sin() / (TAU * cycles))
            } else {
                let f = body.forward.unwrap_or(2);
                for limb in &body.limbs {
                    let beta = swing * limb.gain * (TAU * (cycles * tau + limb.phase)).sin();
                    let (s, co) = beta.sin_cos();
                    for p in &mut out[limb.range.clone()] {
                        let (df, dy) = (p[f] - limb.joint[f], p[1] - limb.joint[1]);
                        p[f] = limb.joint[f] + df * co - dy * s;
                        p[1] = limb.joint[1] + df * s + dy * co;
                    }
                }
                let bob = 0.03 * body.leg * swing * (2.0 * TAU * cycles * tau).cos();
                for p in out.iter_mut() {
                    p[1] += bob;
                }
                distance * tau
            };
            face_and_move(out, body, c, heading, mul(heading, progress));
        }
        Motion::Jump {
            hops,
            height,
            travel,
            squash,
        } => {
            let q = (tau * hops as f32).min(hops as f32 - 1e-4);
            let (hop, w) = (q.floor(), q.fract());
            // Ground contact for the first and last 15 % of each hop, in the air between.
            let g = 0.15;
            let air = ((w - g) / (1.0 - 2.0 * g)).clamp(0.0, 1.0);
            let y = height * 4.0 * air * (1.0 - air);
            let contact = if w < g {
                (PI * w / g).sin()
            } else if w > 1.0 - g {
                (PI * (1.0 - w) / g).sin()
            } else {
                0.0
            };
            let sy = 1.0 - squash * contact;
            let shift = mul(travel, (hop + air) / hops as f32);
            for p in out.iter_mut() {
                *p = [
                    c[0] + (p[0] - c[0]) / sy.sqrt() + shift[0],
                    p[1] * sy + y,
                    c[2] + (p[2] - c[2]) / sy.sqrt() + shift[2],
                ];
            }
        }
        Motion::Squash { amount, cycles } => {
            stretch(out, body, c, 1.0 + amount * (TAU * cycles * tau).sin());
        }
        Motion::Rigid { spin, travel } => {
            let e = ease(tau);
            let shift = mul(travel, e);
            for p in out.iter_mut() {
                let q = yaw(*p, c, spin * e);
                *p = [q[0] + shift[0], q[1], q[2] + shift[2]];
            }
        }
    }
}

/// Volume-preserving scale by `s` along the squash axis (the length of limbless lying shapes, else vertical)
/// and by 1/√s across it; heights stay anchored on the ground, the rest on the rest centre `c`.
fn stretch(out: &mut [V3], body: &Body, c: V3, s: f32) {
    let k = if body.pivot == Pivot::Center && body.limbs.is_empty() {
        body.axis
    } else {
        1
    };
    let anchor = [c[0], 0.0, c[2]];
    for p in out.iter_mut() {
        for (i, x) in p.iter_mut().enumerate() {
            let f = if i == k { s } else { 1.0 / s.sqrt() };
            *x = anchor[i] + (*x - anchor[i]) * f;
        }
    }
}

/// Turn a body with a front towards `heading` (about its vertical centre line), then translate by `shift`.
fn face_and_move(out: &mut [V3], body: &Body, c: V3, heading: V3, shift: V3) {
    let psi = match body.forward {
        // The angle atan2(x, z) of a horizontal direction grows by ψ under `yaw`.
        Some(f) => heading[0].atan2(heading[2]) - if f == 0 { PI / 2.0 } else { 0.0 },
        None => 0.0,
    };
    for p in out.iter_mut() {
        let q = yaw(*p, c, psi);
        *p = [q[0] + shift[0], q[1], q[2] + shift[2]];
    }
}
