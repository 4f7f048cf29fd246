//! Baking a checked glTF scene into frames: channel sampling, the node hierarchy, morph targets and skinning.
//!
//! Everything here works on data that `read.rs` has validated (indices in range, lengths consistent), and the
//! work is bounded by [`MAX_BAKE_STEPS`].

use super::{Ctx, MAX_BAKE_STEPS};
use crate::error::Result;
use crate::skeletal;

pub(super) type Mat = [[f64; 4]; 4]; // column-major, m[col][row], as glTF stores it

pub(super) const IDENTITY: Mat = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

pub(super) fn mul(a: &Mat, b: &Mat) -> Mat {
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, x) in col.iter_mut().enumerate() {
            *x = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

pub(super) fn apply(m: &Mat, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

/// Local matrix T · R · S from translation, unit quaternion (x, y, z, w) and scale.
pub(super) fn trs(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> Mat {
    let [x, y, z, w] = q;
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + z * w),
            2.0 * (x * z - y * w),
        ],
        [
            2.0 * (x * y - z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + x * w),
        ],
        [
            2.0 * (x * z + y * w),
            2.0 * (y * z - x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    let mut m = IDENTITY;
    for c in 0..3 {
        for k in 0..3 {
            m[c][k] = r[c][k] * s[c];
        }
    }
    m[3] = [t[0], t[1], t[2], 1.0];
    m
}

/// Translation, rotation and scale of an affine matrix (the decomposition the gltf crate uses for a node that has
/// a matrix and is animated).
pub(super) fn decompose(m: &Mat) -> ([f64; 3], [f64; 4], [f64; 3]) {
    let t = [m[3][0], m[3][1], m[3][2]];
    let col = |c: usize| [m[c][0], m[c][1], m[c][2]];
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let (x, y, z) = (col(0), col(1), col(2));
    let det =
        x[0] * (y[1] * z[2] - z[1] * y[2]) - y[0] * (x[1] * z[2] - z[1] * x[2]) + z[0] * (x[1] * y[2] - y[1] * x[2]);
    let s = [norm(x), norm(y), det.signum() * norm(z)];
    let [x, y, z] = [x.map(|v| v / s[0]), y.map(|v| v / s[1]), z.map(|v| v / s[2])];
    let trace = x[0] + y[1] + z[2];
    let q = if trace >= 0.0 {
        let r = (1.0 + trace).sqrt();
        let k = 0.5 / r;
        [(y[2] - z[1]) * k, (z[0] - x[2]) * k, (x[1] - y[0]) * k, 0.5 * r]
    } else if x[0] > y[1] && x[0] > z[2] {
        let r = (x[0] - y[1] - z[2] + 1.0).sqrt();
        let k = 0.5 / r;
        [0.5 * r, (y[0] + x[1]) * k, (x[2] + z[0]) * k, (y[2] - z[1]) * k]
    } else if y[1] > z[2] {
        let r = (y[1] - x[0] - z[2] + 1.0).sqrt();
        let k = 0.5 / r;
        [(y[0] + x[1]) * k, 0.5 * r, (z[1] + y[2]) * k, (z[0] - x[2]) * k]
    } else {
        let r = (z[2] - x[0] - y[1] + 1.0).sqrt();
        let k = 0.5 / r;
        [(x[2] + z[0]) * k, (z[1] + y[2]) * k, 0.5 * r, (x[1] - y[0]) * k]
    };
    (t, q, s)
}

/// The node property a channel animates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Property {
    Translation,
    Rotation,
    Scale,
    Weights,
}

/// How a channel interpolates between keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Interpolation {
    Step,
    Linear,
    CubicSpline,
}

/// One animation channel: key times and `width` components per key (3 × for CUBICSPLINE: in-tangent, value,
/// out-tangent). `read.rs` checks `values.len() == times.len() · width · (3 for CUBICSPLINE, else 1)`, times
/// finite, non-empty and non-decreasing, `node` in range.
pub(super) struct Track {
    pub node: usize,
    pub property: Property,
    pub interpolation: Interpolation,
    pub times: Vec<f32>,
    pub values: Vec<f64>,
    pub width: usize,
}

impl Track {
    fn key(&self, k: usize, part: usize) -> &[f64] {
        let stride = if self.interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        let off = (k * stride + if stride == 3 { part } else { 0 }) * self.width;
        &self.values[off..off + self.width]
    }

    /// The channel's value at time `t`.
    fn sample(&self, t: f32) -> Vec<f64> {
        let n = self.times.len();
        let tol = 1e-6 * t.abs().max(1.0);
        if t <= self.times[0] + tol {
            return self.key(0, 1).to_vec();
        }
        if t >= self.times[n - 1] - tol {
            return self.key(n - 1, 1).to_vec();
        }
        let k = self.times.partition_point(|&x| x <= t + tol) - 1;
        let (t0, t1) = (self.times[k] as f64, self.times[k + 1] as f64);
        let dt = t1 - t0;
        let u = ((t as f64 - t0) / dt).clamp(0.0, 1.0);
        let (a, b) = (self.key(k, 1), self.key(k + 1, 1));
        let mut v: Vec<f64> = match self.interpolation {
            Interpolation::Step => a.to_vec(),
            Interpolation::Linear if self.property == Property::Rotation => {
                // Rotation tracks are VEC4 (`read.rs`).
                let q = |v: &[f64]| std::array::from_fn(|k| v[k]);
                skeletal::slerp(q(a), q(b), u).to_vec()
            }
            Interpolation::Linear => a.iter().zip(b).map(|(x, y)| x + u * (y - x)).collect(),
            Interpolation::CubicSpline => {
                let (m0, m1) = (self.key(k, 2), self.key(k + 1, 0));
                let (u2, u3) = (u * u, u * u * u);
                (0..self.width)
                    .map(|i| {
                        (2.0 * u3 - 3.0 * u2 + 1.0) * a[i]
                            + (u3 - 2.0 * u2 + u) * dt * m0[i]
                            + (-2.0 * u3 + 3.0 * u2) * b[i]
                            + (u3 - u2) * dt * m1[i]
                    })
                    .collect()
            }
        };
        if self.property == Property::Rotation {
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.iter_mut().for_each(|x| *x /= norm);
        }
        v
    }
}

/// A node at rest: its parent, TRS (used when animated) and matrix (used otherwise).
pub(super) struct RestNode {
    pub parent: Option<usize>,
    pub trs: ([f64; 3], [f64; 4], [f64; 3]),
    pub matrix: Mat,
}

/// The skin of the mesh node: joint nodes, inverse bind matrices and per-vertex (joint slot, weight) influences.
pub(super) struct Skin {
    pub joints: Vec<usize>,
    pub ibms: Vec<Mat>,
    pub influences: Vec<Vec<(usize, f64)>>,
}

/// Everything baking needs, checked: node parents form a forest, every index is in range, every target has the
/// base's vertex count, `default_weights.len() == targets.len()`.
pub(super) struct Scene {
    pub nodes: Vec<RestNode>,
    pub mesh_node: usize,
    pub base: Vec<[f64; 3]>,
    pub targets: Vec<Vec<[f64; 3]>>,
    pub default_weights: Vec<f64>,
    pub skin: Option<Skin>,
    pub tracks: Vec<Track>,
}

/// World-space vertices of `frames` frames sampled at `f / fps`, frame-major.
pub(super) fn bake(ctx: Ctx, scene: &Scene, frames: usize, fps: f32) -> Result<Vec<[f32; 3]>> {
    let count = scene.nodes.len();
    let n = scene.base.len();
    let mut steps: u64 = 0;
    let mut vertices = Vec::with_capacity(frames * n);
    for f in 0..frames {
        let t = f as f32 / fps;
        let mut pose: Vec<_> = scene.nodes.iter().map(|nd| nd.trs).collect();
        let mut animated = vec![false; count];
        let mut weights = scene.default_weights.clone();
        for tr in &scene.tracks {
            let v = tr.sample(t);
            let p = &mut pose[tr.node];
            match tr.property {
                Property::Translation => p.0 = [v[0], v[1], v[2]],
                Property::Rotation => p.1 = [v[0], v[1], v[2], v[3]],
                Property::Scale => p.2 = [v[0], v[1], v[2]],
                Property::Weights => {
                    weights = v;
                    continue;
                }
            }
            animated[tr.node] = true;
        }
        let active: Vec<(f64, &Vec<[f64; 3]>)> = weights
            .iter()
            .zip(&scene.targets)
            .filter(|(w, _)| **w != 0.0)
            .map(|(&w, t)| (w, t))
            .collect();
        let influences = scene
            .skin
            .as_ref()
            .map_or(0, |s| s.influences.iter().map(Vec::len).sum::<usize>());
        steps = steps.saturating_add((count + n * (1 + active.len()) + influences) as u64);
        if steps > MAX_BAKE_STEPS {
            return Err(ctx.err(
                "animations",
                format!(
                    "baking frame {f} of {frames} needs more than {MAX_BAKE_STEPS} vertex updates (vertices × \
                     (1 + active morph targets + joint influences) per frame)"
                ),
            ));
        }
        let mut global: Vec<Option<Mat>> = vec![None; count];
        let mut world = |i: usize| -> Mat {
            // Parents form a forest (checked), so the chain ends at a root or a computed node.
            let mut chain = vec![i];
            while let Some(p) = scene.nodes[*chain.last().expect("non-empty")].parent {
                if global[p].is_some() {
                    break;
                }
                chain.push(p);
            }
            for &k in chain.iter().rev() {
                let local = if animated[k] {
                    trs(pose[k].0, pose[k].1, pose[k].2)
                } else {
                    scene.nodes[k].matrix
                };
                global[k] = Some(match scene.nodes[k].parent.and_then(|p| global[p]) {
                    Some(pm) => mul(&pm, &local),
                    None => local,
                });
            }
            global[i].expect("computed")
        };
        // (morph) p = base + Σ_k w_k · target_k
        let morphed = scene.base.iter().enumerate().map(|(v, b)| {
            let mut p = *b;
            for (w, tgt) in &active {
                for c in 0..3 {
                    p[c] += w * tgt[v][c];
                }
            }
            p
        });
        match &scene.skin {
            Some(skin) => {
                // (skin) v = Σ_i w_i · G(joint_i) · IBM_i · p, weights normalised to sum 1
                let skin_mats: Vec<Mat> = skin
                    .joints
                    .iter()
                    .zip(&skin.ibms)
                    .map(|(&j, ibm)| mul(&world(j), ibm))
                    .collect();
                for (p, inf) in morphed.zip(&skin.influences) {
                    let total: f64 = inf.iter().map(|(_, w)| w).sum();
                    let mut out = [0.0; 3];
                    for &(j, w) in inf {
                        let q = apply(&skin_mats[j], p);
                        (0..3).for_each(|c| out[c] += w / total * q[c]);
                    }
                    vertices.push(out.map(|x| x as f32));
                }
            }
            None => {
                let m = world(scene.mesh_node);
                vertices.extend(morphed.map(|p| apply(&m, p).map(|x| x as f32)));
            }
        }
    }
    Ok(vertices)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trs_rotates_and_translates() {
        let s = 0.5f64.sqrt();
        let m = trs([1.0, 0.0, 0.0], [0.0, 0.0, s, s], [2.0, 2.0, 2.0]);
        let p = apply(&m, [1.0, 0.0, 0.0]);
        assert!(
            (p[0] - 1.0).abs() < 1e-12 && (p[1] - 2.0).abs() < 1e-12 && p[2].abs() < 1e-12,
            "{p:?}"
        );
        assert_eq!(mul(&IDENTITY, &m), m);
    }

    #[test]
    fn decompose_inverts_trs() {
        let q = {
            let v = [0.1f64, -0.7, 0.3, 0.6];
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.map(|x| x / n)
        };
        for s in [[2.0, 0.5, 1.5], [1.0, 1.0, -3.0]] {
            let m = trs([1.0, -2.0, 3.0], q, s);
            let (t2, q2, s2) = decompose(&m);
            let m2 = trs(t2, q2, s2);
            for c in 0..4 {
                for r in 0..4 {
                    assert!((m[c][r] - m2[c][r]).abs() < 1e-12, "{s:?}: {m:?} vs {m2:?}");
                }
            }
        }
    }

    #[test]
    fn slerp_halfway_is_45_degrees() {
        let s = 0.5f64.sqrt();
        let q = skeletal::slerp([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, s, s], 0.5);
        let half = (std::f64::consts::PI / 8.0).sin();
        assert!((q[2] - half).abs() < 1e-12, "{q:?}");
    }
}
