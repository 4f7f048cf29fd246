//! Rest meshes of the synthetic shape families: closed sphere-topology parts (ellipsoids, capsules, swept tubes,
//! noisy blobs) and one open grid (the cloth sheet), with a vertex budget spread over the parts.

use std::f32::consts::{PI, TAU};
use std::ops::Range;

use super::{ShapeFamily, V3};
use crate::error::{DataError, Result};
use crate::rng::{DataRng, Rng};

/// Where bending and twisting are anchored along the main axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Pivot {
    /// Nothing below this coordinate of the main axis deforms (standing shapes; a humanoid's hips).
    Base(f32),
    /// The middle of the main axis stays; both ends move (lying shapes).
    Center,
}

/// A rigid limb of an articulated body: its vertices swing about `joint` in the vertical-forward plane.
#[derive(Debug, Clone)]
pub(super) struct Limb {
    pub range: Range<usize>,
    pub joint: V3,
    /// Phase of the swing in cycles (0 or 0.5: legs in antiphase).
    pub phase: f32,
    /// Swing amplitude relative to the legs (arms swing less).
    pub gain: f32,
}

/// A rest mesh and what the motions need to know about it.
#[derive(Debug, Clone)]
pub(super) struct Body {
    pub pos: Vec<V3>,
    pub faces: Vec<[u32; 3]>,
    /// Main axis (0 = x, 1 = y): bending, twisting and waves run along it.
    pub axis: usize,
    pub pivot: Pivot,
    /// Facing direction index (0 = +x, 2 = +z) for locomotion; `None` for shapes without a front.
    pub forward: Option<usize>,
    pub limbs: Vec<Limb>,
    /// Leg length (joint to ground) for articulated bodies.
    pub leg: f32,
    /// Adjectives of the caption, e.g. `["small", "lumpy"]`.
    pub words: Vec<&'static str>,
    pub noun: &'static str,
    /// True when every part is a closed, consistently oriented surface.
    pub closed: bool,
}

/// Triangle mesh under construction.
#[derive(Default)]
pub(super) struct Mesh {
    pub pos: Vec<V3>,
    pub faces: Vec<[u32; 3]>,
}

impl Mesh {
    /// A closed sphere-topology part with `rings` rings of `segs` vertices plus two poles; `f(ring, t, phi)` gives
    /// the position, t ∈ [0, 1] from pole to pole (ring 0 and `rings + 1` are the poles), phi ∈ [0, 2π).
    /// With a right-handed frame (axis, e1, e2 = axis × e1) and phi turning e1 towards e2, faces point outwards.
    fn sphere_part(&mut self, rings: usize, segs: usize, f: impl Fn(usize, f32, f32) -> V3) -> Range<usize> {
        let b = self.pos.len();
        self.pos.push(f(0, 0.0, 0.0));
        for i in 1..=rings {
            let t = i as f32 / (rings + 1) as f32;
            for j in 0..segs {
                self.pos.push(f(i, t, TAU * j as f32 / segs as f32));
            }
        }
        self.pos.push(f(rings + 1, 1.0, 0.0));
        let v = |i: usize, j: usize| (b + 1 + (i - 1) * segs + j % segs) as u32;
        let (p0, p1) = (b as u32, (b + 1 + rings * segs) as u32);
        for j in 0..segs {
            self.faces.push([p0, v(1, j + 1), v(1, j)]);
            for i in 1..rings {
                let (a, bb, c, d) = (v(i, j), v(i, j + 1), v(i + 1, j + 1), v(i + 1, j));
                self.faces.push([a, bb, c]);
                self.faces.push([a, c, d]);
            }
            self.faces.push([p1, v(rings, j), v(rings, j + 1)]);
        }
        b..self.pos.len()
    }

    /// An open `nx × nz` grid, `f(u, v)` with u, v ∈ [0, 1].
    fn grid(&mut self, nx: usize, nz: usize, f: impl Fn(f32, f32) -> V3) {
        let b = self.pos.len();
        for i in 0..nx {
            for k in 0..nz {
                self.pos.push(f(i as f32 / (nx - 1) as f32, k as f32 / (nz - 1) as f32));
            }
        }
        let v = |i: usize, k: usize| (b + i * nz + k) as u32;
        for i in 0..nx - 1 {
            for k in 0..nz - 1 {
                self.faces.push([v(i, k), v(i, k + 1), v(i + 1, k + 1)]);
                self.faces.push([v(i, k), v(i + 1, k + 1), v(i + 1, k)]);
            }
        }
    }

    /// A capsule from `p0` (radius `r0`) to `p1` (radius `r1`) with hemispherical-ish ends, rings spaced by arc.
    pub(super) fn capsule(&mut self, (rings, segs): (usize, usize), p0: V3, p1: V3, r0: f32, r1: f32) -> Range<usize> {
        let d = sub(p1, p0);
        let len = norm(d).max(1e-6);
        let a = scale(d, 1.0 / len);
        let (e1, e2) = frame_of(a);
        let (c0, c1) = (PI * r0 / 2.0, PI * r1 / 2.0);
        let total = c0 + len + c1;
        self.sphere_part(rings, segs, |_, t, phi| {
            let q = t * total;
            let (axial, rho) = if q < c0 {
                let th = q / r0;
                (-r0 * th.cos(), r0 * th.sin())
            } else if q > c0 + len {
                let th = (total - q) / r1;
                (len + r1 * th.cos(), r1 * th.sin())
            } else {
                let s = (q - c0) / len;
                (q - c0, r0 + (r1 - r0) * s)
            };
            add(
                add(p0, scale(a, axial)),
                add(scale(e1, rho * phi.cos()), scale(e2, rho * phi.sin())),
            )
        })
    }

    /// An ellipsoid with centre `c` and radii `r` along x, y, z, poles on the y axis.
    pub(super) fn ellipsoid(&mut self, res: (usize, usize), c: V3, r: V3) -> Range<usize> {
        self.sphere_part(res.0, res.1, |_, t, phi| {
            let u = sphere_dir(t, phi);
            [c[0] + r[0] * u[0], c[1] + r[1] * u[1], c[2] + r[2] * u[2]]
        })
    }

    /// A tube swept along `curve(s)`, s ∈ [0, 1] of arc length `length`, radius `r` (times `ratio` across),
    /// with rounded ends one radius long. Frames are parallel-transported along the curve.
    fn sweep(
        &mut self,
        res: (usize, usize),
        length: f32,
        r: f32,
        ratio: f32,
        curve: impl Fn(f32) -> V3,
    ) -> Range<usize> {
        let (rings, segs) = res;
        let h = 1e-3;
        let tangent = |s: f32| {
            let d = sub(curve((s + h).min(1.0)), curve((s - h).max(0.0)));
            scale(d, 1.0 / norm(d).max(1e-12))
        };
        let mut frames = Vec::with_capacity(rings + 2);
        let t0 = tangent(0.0);
        let mut n = frame_of(t0).0;
        for i in 0..rings + 2 {
            let s = i as f32 / (rings + 1) as f32;
            let t = tangent(s);
            n = sub(n, scale(t, dot(n, t)));
            n = scale(n, 1.0 / norm(n).max(1e-12));
            frames.push((curve(s), n, cross(t, n)));
        }
        let e = (r / length).min(0.5);
        self.sphere_part(rings, segs, |i, t, phi| {
            let (c, n, b) = frames[i];
            let d = t.min(1.0 - t);
            let rho = if d < e {
                r * (1.0 - (1.0 - d / e).powi(2)).max(0.0).sqrt()
            } else {
                r
            };
            add(c, add(scale(n, rho * phi.cos()), scale(b, rho * ratio * phi.sin())))
        })
    }
}

/// Unit direction on the sphere, poles on ±y, in the right-handed frame (y, x, y × x = −z).
fn sphere_dir(t: f32, phi: f32) -> V3 {
    let th = PI * t;
    let rho = th.sin();
    [rho * phi.cos(), -th.cos(), -rho * phi.sin()]
}

/// Ring and segment counts of parts with given (length, girth) so that the total vertex count is as close to
/// `target` as one ring allows and inside `lo..=hi`.
pub(super) fn allocate(target: usize, lo: usize, hi: usize, parts: &[(f32, f32)]) -> Result<Vec<(usize, usize)>> {
    let area: f32 = parts.iter().map(|(l, g)| l * g).sum();
    let mut res: Vec<(usize, usize)> = parts
        .iter()
        .map(|&(l, g)| {
            let n = target as f32 * l * g / area;
            let segs = ((n * g / l).sqrt().round() as usize).clamp(6, 96);
            let rings = ((n / segs as f32).round() as usize).max(2);
            (rings, segs)
        })
        .collect();
    let count = |res: &[(usize, usize)]| res.iter().map(|(r, s)| r * s + 2).sum::<usize>();
    let biggest = |res: &[(usize, usize)], shrink: bool| {
        (0..res.len())
            .filter(|&k| !shrink || res[k].0 > 2)
            .max_by_key(|&k| res[k].0 * res[k].1)
    };
    // First as close to the target as one ring of the biggest part allows, then (one way only) inside lo..=hi.
    let slack = res.iter().map(|r| r.1).max().unwrap_or(0) / 2;
    for _ in 0..100_000 {
        let n = count(&res);
        if n > target + slack {
            match biggest(&res, true) {
                Some(k) => res[k].0 -= 1,
                None => break,
            }
        } else if n + slack < target {
            if let Some(k) = biggest(&res, false) {
                res[k].0 += 1;
            }
        } else {
            break;
        }
    }
    while count(&res) > hi {
        match biggest(&res, true) {
            Some(k) => res[k].0 -= 1,
            None => break,
        }
    }
    while count(&res) < lo {
        match biggest(&res, false) {
            Some(k) => res[k].0 += 1,
            None => break,
        }
    }
    let n = count(&res);
    if n < lo || n > hi {
        return Err(DataError::new(
            "synth",
            "vertices",
            format!("cannot fit a mesh of these parts into {lo}..={hi} vertices (got {n}, target {target})"),
        ));
    }
    Ok(res)
}

/// Draw a rest body of `family` with about `target` vertices, inside `lo..=hi`.
pub(super) fn build(family: ShapeFamily, target: usize, lo: usize, hi: usize, r: &mut DataRng) -> Result<Body> {
    let mut m = Mesh::default();
    let mut body = Body {
        pos: Vec::new(),
        faces: Vec::new(),
        axis: 1,
        pivot: Pivot::Base(0.0),
        forward: None,
        limbs: Vec::new(),
        leg: 0.0,
        words: Vec::new(),
        noun: family.noun(),
        closed: true,
    };
    let pick = |x: f32, lo_cut: f32, hi_cut: f32, lo_word: &'static str, hi_word: &'static str| {
        if x < lo_cut {
            Some(lo_word)
        } else if x > hi_cut {
            Some(hi_word)
        } else {
            None
        }
    };
    match family {
        ShapeFamily::Blob => {
            let rad = r.random_range(0.4f32..0.9);
            let stretch = [
                r.random_range(0.8f32..1.2),
                r.random_range(0.9f32..1.4),
                r.random_range(0.8f32..1.2),
            ];
            let lump = r.random_range(0.05f32..0.3);
            let waves: Vec<(V3, f32, f32, f32)> = (0..6)
                .map(|_| {
                    let d = unit([
                        r.random_range(-1.0f32..1.0),
                        r.random_range(-1.0..1.0),
                        r.random_range(-1.0..1.0),
                    ]);
                    (
                        d,
                        r.random_range(0.8f32..2.2),
                        r.random_range(0.4f32..1.0),
                        r.random_range(0.0..TAU),
                    )
                })
                .collect();
            let wsum: f32 = waves.iter().map(|w| w.2).sum();
            let res = allocate(target, lo, hi, &[(PI * rad, TAU * rad)])?;
            m.sphere_part(res[0].0, res[0].1, |_, t, phi| {
                let u = sphere_dir(t, phi);
                let noise: f32 = waves
                    .iter()
                    .map(|(d, f, a, p)| a * (f * PI * dot(*d, u) + p).sin())
                    .sum();
                let k = rad * (1.0 + 1.5 * lump * noise / wsum);
                [0, 1, 2].map(|i| k * stretch[i] * u[i])
            });
            body.words.extend(pick(rad, 0.55, 0.75, "small", "large"));
            body.words.extend(pick(lump, 0.12, 0.2, "smooth", "lumpy"));
        }
        ShapeFamily::Tube => {
            let height = r.random_range(1.0f32..2.2);
            let rad = height * r.random_range(0.06f32..0.2);
            let ratio = r.random_range(0.5f32..0.8);
            let taper = r.random_range(0.6f32..1.0);
            let (ribs, rib) = (r.random_range(3..=6) as f32, r.random_range(0.06f32..0.14));
            let res = allocate(target, lo, hi, &[(height + rad * 2.0, TAU * rad)])?;
            m.sweep(res[0], height, rad, ratio, |s| [0.0, s * height, 0.0]);
            // Taper towards the top and flute the sides with `ribs` ridges, so that twisting shows.
            for p in &mut m.pos {
                let flute = 1.0 + rib * (ribs * p[2].atan2(p[0])).cos();
                let k = (1.0 + (taper - 1.0) * (p[1] / height).clamp(0.0, 1.0)) * flute;
                p[0] *= k;
                p[2] *= k;
            }
            // Adjective order: size, then build.
            body.words.extend(pick(height, 1.3, 1.9, "short", "tall"));
            body.words.extend(pick(rad / height, 0.1, 0.15, "thin", "thick"));
        }
        ShapeFamily::Humanoid => {
            let h = r.random_range(1.5f32..1.9);
            let w = r.random_range(0.75f32..1.3);
            let hip = 0.47 * h;
            let (leg_r, arm_r) = (0.04 * h * w, 0.03 * h * w);
            let torso = [0.13 * h * w, 0.17 * h, 0.08 * h * w];
            let torso_c = [0.0, hip + 0.14 * h, 0.0];
            let head_r = 0.065 * h;
            let head_c = [0.0, hip + 0.31 * h + head_r, 0.0];
            let shoulder_x = torso[0] + arm_r;
            let shoulder_y = hip + 0.27 * h;
            let leg_len = hip - leg_r;
            let arm_len = 0.3 * h;
            let parts = [
                (torso[1] * PI, TAU * torso[0]),
                (head_r * PI, TAU * head_r),
                (leg_len + 2.0 * leg_r, TAU * leg_r),
                (leg_len + 2.0 * leg_r, TAU * leg_r),
                (arm_len + 2.0 * arm_r, TAU * arm_r),
                (arm_len + 2.0 * arm_r, TAU * arm_r),
            ];
            let res = allocate(target, lo, hi, &parts)?;
            m.ellipsoid(res[0], torso_c, torso);
            m.ellipsoid(res[1], head_c, [head_r, head_r * 1.1, head_r]);
            for (k, side) in [(2, 1.0f32), (3, -1.0)] {
                let x = side * 0.06 * h * w;
                let range = m.capsule(res[k], [x, hip, 0.0], [x, leg_r, 0.0], leg_r, leg_r * 0.9);
                let phase = if side > 0.0 { 0.0 } else { 0.5 };
                body.limbs.push(Limb {
                    range,
                    joint: [x, hip, 0.0],
                    phase,
                    gain: 1.0,
                });
            }
            for (k, side) in [(4, 1.0f32), (5, -1.0)] {
                let x = side * shoulder_x;
                let range = m.capsule(
                    res[k],
                    [x, shoulder_y, 0.0],
                    [x, shoulder_y - arm_len, 0.0],
                    arm_r,
                    arm_r * 0.8,
                );
                let phase = if side > 0.0 { 0.5 } else { 0.0 };
                body.limbs.push(Limb {
                    range,
                    joint: [x, shoulder_y, 0.0],
                    phase,
                    gain: 0.7,
                });
            }
            body.pivot = Pivot::Base(hip);
            body.forward = Some(2);
            body.leg = hip;
            body.words.extend(pick(w, 0.9, 1.1, "slender", "stocky"));
        }
        ShapeFamily::Quadruped => {
            let len = r.random_range(0.8f32..1.6);
            let leg_f = r.random_range(0.3f32..0.6);
            let girth = r.random_range(0.8f32..1.2);
            let leg = leg_f * len;
            let body_r = [0.5 * len, 0.16 * len * girth, 0.15 * len * girth];
            let body_c = [0.0, leg + body_r[1] * 0.6, 0.0];
            let leg_r = 0.05 * len * girth;
            let head_r = 0.1 * len;
            let head_c = [0.6 * len, body_c[1] + 0.25 * len, 0.0];
            let neck0 = [0.38 * len, body_c[1] + 0.05 * len, 0.0];
            let tail0 = [-0.45 * len, body_c[1] + 0.05 * len, 0.0];
            let tail1 = [-0.75 * len, body_c[1] + 0.2 * len, 0.0];
            let tail_r = 0.025 * len;
            let neck_r = 0.06 * len * girth;
            let mut parts = vec![
                (body_r[0] * PI, TAU * body_r[1]),
                (head_r * PI, TAU * head_r),
                (norm(sub(head_c, neck0)) + 2.0 * neck_r, TAU * neck_r),
                (0.34 * len + 2.0 * tail_r, TAU * tail_r),
            ];
            parts.extend([(leg + 2.0 * leg_r, TAU * leg_r); 4]);
            let res = allocate(target, lo, hi, &parts)?;
            m.ellipsoid(res[0], body_c, body_r);
            m.ellipsoid(res[1], head_c, [head_r * 1.3, head_r, head_r * 0.9]);
            m.capsule(res[2], neck0, head_c, neck_r, neck_r * 0.8);
            m.capsule(res[3], tail0, tail1, tail_r, tail_r * 0.5);
            // Trot: diagonal legs move together.
            let legs = [
                (0.32, 0.09, 0.0),
                (0.32, -0.09, 0.5),
                (-0.32, 0.09, 0.5),
                (-0.32, -0.09, 0.0),
            ];
            for (k, &(fx, fz, phase)) in legs.iter().enumerate() {
                let joint = [fx * len, leg, fz * len * girth];
                let foot = [fx * len, leg_r, fz * len * girth];
                let range = m.capsule(res[4 + k], joint, foot, leg_r, leg_r * 0.8);
                body.limbs.push(Limb {
                    range,
                    joint,
                    phase,
                    gain: 1.0,
                });
            }
            body.axis = 0;
            body.pivot = Pivot::Center;
            body.forward = Some(0);
            body.leg = leg;
            body.words.extend(pick(leg_f, 0.4, 0.5, "short-legged", "long-legged"));
        }
        ShapeFamily::Sheet => {
            let lx = r.random_range(1.0f32..2.0);
            let aspect = r.random_range(0.4f32..1.0);
            let lz = lx * aspect;
            let nz = ((target as f32 * aspect).sqrt().round() as usize).max(2);
            let mut nx = (target as f32 / nz as f32).round() as usize;
            while nx * nz > hi {
                nx -= 1;
            }
            while nx * nz < lo {
                nx += 1;
            }
            m.grid(nx, nz, |u, v| [(u - 0.5) * lx, 0.0, (v - 0.5) * lz]);
            body.axis = 0;
            body.pivot = Pivot::Center;
            body.closed = false;
            body.words.extend(pick(lx, 1.3, 1.7, "small", "large"));
            body.words.extend(pick(aspect, 0.6, 0.85, "narrow", "square"));
        }
        ShapeFamily::Worm => {
            let len = r.random_range(1.0f32..2.5);
            let rad = len * r.random_range(0.025f32..0.07);
            let wiggle = len * r.random_range(0.05f32..0.12);
            let phase = r.random_range(0.0f32..TAU);
            let res = allocate(target, lo, hi, &[(len, TAU * rad)])?;
            m.sweep(res[0], len, rad, 1.0, |s| {
                [(s - 0.5) * len, rad, wiggle * (TAU * s + phase).sin()]
            });
            body.axis = 0;
            body.pivot = Pivot::Center;
            body.forward = Some(0);
            body.words.extend(pick(len, 1.5, 2.0, "short", "long"));
            body.words.extend(pick(rad / len, 0.04, 0.055, "thin", "fat"));
        }
        ShapeFamily::Helix => {
            let height = r.random_range(0.8f32..1.8);
            let coil = r.random_range(0.2f32..0.45);
            let turns = r.random_range(2.0f32..5.0);
            let wire = r.random_range(0.03f32..0.07);
            let length = ((TAU * coil * turns).powi(2) + height * height).sqrt();
            let res = allocate(target, lo, hi, &[(length, TAU * wire)])?;
            m.sweep(res[0], length, wire, 1.0, |s| {
                let a = TAU * turns * s;
                [coil * a.cos(), wire + s * height, coil * a.sin()]
            });
            body.words.extend(pick(turns / height, 2.2, 3.5, "loosely", "tightly"));
            if body.words.is_empty() {
                body.words.push("coiled");
            } else {
                body.words[0] = if body.words[0] == "loosely" {
                    "loosely coiled"
                } else {
                    "tightly coiled"
                };
            }
        }
    }
    // Stand on the ground plane y = 0.
    let ground = m.pos.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
    for p in &mut m.pos {
        p[1] -= ground;
    }
    if let Pivot::Base(b) = &mut body.pivot {
        *b -= ground;
    }
    for limb in &mut body.limbs {
        limb.joint[1] -= ground;
    }
    body.pos = m.pos;
    body.faces = m.faces;
    Ok(body)
}

pub(super) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(super) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(super) fn scale(a: V3, k: f32) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
pub(super) fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(super) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(super) fn norm(a: V3) -> f32 {
    dot(a, a).sqrt()
}
pub(super) fn unit(a: V3) -> V3 {
    scale(a, 1.0 / norm(a).max(1e-6))
}
/// Two unit vectors completing `a` to a right-handed frame (a, e1, e2 = a × e1).
fn frame_of(a: V3) -> (V3, V3) {
    let helper = if a[1].abs() < 0.9 {
        [0.0, 1.0, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let e1 = unit(cross(helper, a));
    (e1, cross(a, e1))
}
