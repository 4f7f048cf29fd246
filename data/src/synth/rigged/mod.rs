//! Rigged procedural characters (`any4d data synth --family rigged`, docs/method.md §2.8, (D4)): a skeleton drawn from
//! one of six templates with random proportions and extra limbs, a closed skin of capsules around its bones with
//! linear blend skinning weights, and an action driven as joint rotations over time.
//!
//! Every template is built in one canonical frame — facing +x, y up, its right side towards +z, standing on
//! y = 0 — and the whole clip is then turned to a random heading about y. A bone rotates about its head (the joint
//! it hangs from); a skin vertex follows the bone nearest to it and, close to that bone's head, half its parent.

mod actions;
mod caption;
mod skeletons;

use super::shapes::{Mesh, allocate, dot, norm, sub};
use super::{RiggedKinds, SynthConfig, V3};
use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::formats::skeletal::{self, Mat};
use crate::rng::{DataRng, Rng, rng};

pub use actions::Action;
pub use skeletons::Template;

/// Most bones a rig may have.
pub const MAX_BONES: usize = 64;

/// Shortest bone, in metres: a bone shorter than this has no direction to rotate about.
const MIN_BONE: f32 = 1e-3;

/// Near its head a bone's skin blends with its parent over this fraction of the bone's length.
const BLEND: f32 = 0.3;

/// One bone of a rig, in the canonical rest frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Bone {
    /// The bone it hangs from; parents come before their children (which rules out cycles).
    pub parent: Option<usize>,
    /// The joint it rotates about.
    pub head: V3,
    pub tail: V3,
}

/// A chain of bones from the body outwards (a leg: thigh, shin, foot) and where it sits.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Chain {
    pub bones: Vec<usize>,
    /// +1 on the right (+z), −1 on the left, 0 on the midline.
    pub side: f32,
    /// Phase offset of a gait cycle, in cycles.
    pub phase: f32,
}

/// One closed capsule of the skin and the bones its vertices may follow (the nearest one wins).
#[derive(Debug, Clone)]
struct Part {
    from: V3,
    to: V3,
    radius: (f32, f32),
    bones: Vec<usize>,
}

/// A character: skeleton, the groups the actions drive, skin parts and its caption words.
#[derive(Debug, Clone)]
pub(super) struct Rig {
    pub template: Template,
    pub bones: Vec<Bone>,
    /// Root first, then up the trunk to the chest (the arms' parent).
    pub spine: Vec<usize>,
    pub neck: Vec<usize>,
    pub head: Option<usize>,
    pub tail: Vec<usize>,
    pub legs: Vec<Chain>,
    pub arms: Vec<Chain>,
    pub wings: Vec<Chain>,
    /// A snake's body, from behind the head to the tail tip.
    pub body: Vec<usize>,
    /// Hip height (legged) or body radius (snake), metres.
    pub leg: f32,
    /// Body length along x, metres.
    pub length: f32,
    parts: Vec<Part>,
    /// Adjectives, then the noun, e.g. `["tall", "four-armed", "figure"]`.
    pub words: Vec<String>,
}

impl Rig {
    fn new(template: Template) -> Self {
        Self {
            template,
            bones: Vec::new(),
            spine: Vec::new(),
            neck: Vec::new(),
            head: None,
            tail: Vec::new(),
            legs: Vec::new(),
            arms: Vec::new(),
            wings: Vec::new(),
            body: Vec::new(),
            leg: 0.0,
            length: 0.0,
            parts: Vec::new(),
            words: Vec::new(),
        }
    }

    /// Adds a bone and returns its index.
    fn bone(&mut self, parent: Option<usize>, head: V3, tail: V3) -> usize {
        self.bones.push(Bone { parent, head, tail });
        self.bones.len() - 1
    }

    /// A chain of bones through `points` (joint positions), the first hanging from `parent`.
    fn chain(&mut self, parent: usize, points: &[V3]) -> Vec<usize> {
        let mut up = parent;
        let mut out = Vec::with_capacity(points.len().saturating_sub(1));
        for w in points.windows(2) {
            up = self.bone(Some(up), w[0], w[1]);
            out.push(up);
        }
        out
    }

    /// A skin capsule from `from` to `to` whose vertices follow the nearest of `bones`.
    fn part(&mut self, from: V3, to: V3, radius: (f32, f32), bones: &[usize]) {
        self.parts.push(Part {
            from,
            to,
            radius,
            bones: bones.to_vec(),
        });
    }

    /// A capsule around each of `bones`, radii interpolated from `r0` at the first head to `r1` at the last tail.
    fn skin_each(&mut self, bones: &[usize], r0: f32, r1: f32) {
        let n = bones.len().max(1) as f32;
        for (k, &b) in bones.iter().enumerate() {
            let (a, c) = (r0 + (r1 - r0) * k as f32 / n, r0 + (r1 - r0) * (k + 1) as f32 / n);
            let (head, tail) = (self.bones[b].head, self.bones[b].tail);
            self.part(head, tail, (a, c), &[b]);
        }
    }
}

/// A rig's skin: the rest mesh and each vertex's influences (bone, weight > 0), in the form the readers' linear
/// blend skinning takes (`skeletal::skin_frame`).
#[derive(Debug, Clone)]
pub(super) struct Skin {
    pub pos: Vec<V3>,
    pub faces: Vec<[u32; 3]>,
    bind: Vec<[f64; 3]>,
    influences: skeletal::Influences,
}

/// The skeleton's own checks: at least one bone and at most [`MAX_BONES`], one root (bone 0), parents before
/// children (no cycle), finite joints, no bone shorter than a millimetre.
pub fn check_bones(bones: &[Bone]) -> Result<()> {
    let err = |field: String, reason: String| Err(DataError::new("synth:rigged", field, reason));
    if bones.is_empty() || bones.len() > MAX_BONES {
        return err(
            "bones".into(),
            format!("needs 1..={MAX_BONES} bones, got {}", bones.len()),
        );
    }
    for (i, b) in bones.iter().enumerate() {
        match (i, b.parent) {
            (0, None) => {}
            (0, Some(p)) => return err("bones[0].parent".into(), format!("the root has a parent ({p})")),
            (_, None) => return err(format!("bones[{i}].parent"), "a second root".into()),
            (_, Some(p)) if p >= i => {
                return err(
                    format!("bones[{i}].parent"),
                    format!("parent {p} does not come before the bone (a cycle or a forward reference)"),
                );
            }
            _ => {}
        }
        if b.head.iter().chain(&b.tail).any(|x| !x.is_finite()) {
            return err(format!("bones[{i}]"), "a joint is not finite".into());
        }
        let len = norm(sub(b.tail, b.head));
        if len < MIN_BONE {
            return err(
                format!("bones[{i}]"),
                format!("zero-length bone ({len:e} m; at least {MIN_BONE} m)"),
            );
        }
    }
    Ok(())
}

/// The skin's own checks: every influence names a bone, every weight is finite and non-negative, and every
/// vertex has weights that sum to 1 (a vertex with all-zero weights would not move with any bone).
pub fn check_weights(weights: &[[(usize, f32); 2]], bones: usize) -> Result<()> {
    for (v, w) in weights.iter().enumerate() {
        let field = || format!("weights[{v}]");
        if let Some((b, _)) = w.iter().find(|(b, _)| *b >= bones) {
            return Err(DataError::new("synth:rigged", field(), format!("bone {b} of {bones}")));
        }
        if w.iter().any(|(_, x)| !x.is_finite() || *x < 0.0) {
            return Err(DataError::new("synth:rigged", field(), format!("weights {w:?}")));
        }
        let sum: f32 = w.iter().map(|(_, x)| x).sum();
        if (sum - 1.0).abs() > 1e-4 {
            return Err(DataError::new(
                "synth:rigged",
                field(),
                format!("weights sum to {sum}, not 1 (all-zero weights leave the vertex behind)"),
            ));
        }
    }
    Ok(())
}

/// Weights of a rest position on a part: the nearest of the part's bones, blended with its parent near its head.
fn weigh(bones: &[Bone], candidates: &[usize], p: V3) -> [(usize, f32); 2] {
    let mut best = (candidates[0], f32::INFINITY, 0.0);
    for &b in candidates {
        let (h, t) = (bones[b].head, bones[b].tail);
        let d = sub(t, h);
        let s = dot(sub(p, h), d) / dot(d, d).max(1e-12);
        let c = s.clamp(0.0, 1.0);
        let q = [h[0] + d[0] * c, h[1] + d[1] * c, h[2] + d[2] * c];
        let dist = norm(sub(p, q));
        if dist < best.1 {
            best = (b, dist, s);
        }
    }
    let (b, _, s) = best;
    match bones[b].parent {
        Some(parent) if s < BLEND => {
            let wp = 0.5 * (1.0 - s / BLEND).min(1.0);
            [(b, 1.0 - wp), (parent, wp)]
        }
        _ => [(b, 1.0), (b, 0.0)],
    }
}

/// The rig's skin with about `target` vertices (inside `lo..=hi`): its parts' capsules and their weights.
fn skin(rig: &Rig, target: usize, lo: usize, hi: usize) -> Result<Skin> {
    let sizes: Vec<(f32, f32)> = rig
        .parts
        .iter()
        .map(|p| {
            let r = p.radius.0.max(p.radius.1);
            (
                norm(sub(p.to, p.from)) + p.radius.0 + p.radius.1,
                std::f32::consts::TAU * r,
            )
        })
        .collect();
    let res = allocate(target, lo, hi, &sizes)?;
    let mut m = Mesh::default();
    let mut weights = Vec::with_capacity(target);
    for (part, &res) in rig.parts.iter().zip(&res) {
        let range = m.capsule(res, part.from, part.to, part.radius.0, part.radius.1);
        weights.extend(m.pos[range].iter().map(|&p| weigh(&rig.bones, &part.bones, p)));
    }
    check_weights(&weights, rig.bones.len())?;
    let influences = weights
        .iter()
        .map(|w| {
            w.iter()
                .filter(|(_, x)| *x > 0.0)
                .map(|&(b, x)| (b, f64::from(x)))
                .collect()
        })
        .collect();
    Ok(Skin {
        bind: m.pos.iter().map(|p| p.map(f64::from)).collect(),
        pos: m.pos,
        faces: m.faces,
        influences,
    })
}

/// What an action sets on one frame, in the canonical frame.
#[derive(Debug, Clone)]
pub(super) struct Pose {
    /// Local rotation of each bone about its head, a unit quaternion `(x, y, z, w)`.
    pub rot: Vec<[f64; 4]>,
    /// Uniform scale of each bone about its head (breathing).
    pub scale: Vec<f64>,
    /// Rotation of the whole body about `pivot` (turning, falling over).
    pub body: [f64; 4],
    pub pivot: V3,
    /// Translation of the whole body (travel).
    pub shift: V3,
    /// `Some(h)`: the frame is moved up or down so that its lowest vertex is at height h (feet on the ground, or
    /// h above it in a jump); `None`: it stays where the skeleton puts it (flight).
    pub ground: Option<f32>,
}

impl Pose {
    pub(super) fn rest(bones: usize) -> Self {
        Self {
            rot: vec![[0.0, 0.0, 0.0, 1.0]; bones],
            scale: vec![1.0; bones],
            body: [0.0, 0.0, 0.0, 1.0],
            pivot: [0.0; 3],
            shift: [0.0; 3],
            ground: Some(0.0),
        }
    }
}

/// `T(pivot) · R(q) · S(s) · T(−pivot)`.
fn about(pivot: V3, q: [f64; 4], s: f64) -> Mat {
    let p = pivot.map(f64::from);
    let m = skeletal::trs(p, q, [s; 3]);
    let back = skeletal::trs(p.map(|x| -x), [0.0, 0.0, 0.0, 1.0], [1.0; 3]);
    skeletal::mul(&m, &back)
}

/// Each bone's transform from rest to posed (docs/method.md (D4)),
/// with the whole-body rotation, the travel and the heading (yaw about y, degrees) applied last.
fn transforms(bones: &[Bone], pose: &Pose, heading: f64) -> Vec<Mat> {
    let locals: Vec<Mat> = bones
        .iter()
        .enumerate()
        .map(|(i, b)| about(b.head, pose.rot[i], pose.scale[i]))
        .collect();
    let parents: Vec<Option<usize>> = bones.iter().map(|b| b.parent).collect();
    let world = skeletal::mul(
        &skeletal::axis_rotation(1, heading),
        &skeletal::mul(
            &skeletal::trs(pose.shift.map(f64::from), [0.0, 0.0, 0.0, 1.0], [1.0; 3]),
            &about(pose.pivot, pose.body, 1.0),
        ),
    );
    skeletal::globals(&parents, &locals)
        .iter()
        .map(|g| skeletal::mul(&world, g))
        .collect()
}

/// The posed skin of one frame into `out` (replacing what it held), put on the ground as the pose asks.
fn pose_frame(skin: &Skin, bones: &[Bone], pose: &Pose, heading: f64, out: &mut Vec<V3>) {
    out.clear();
    skeletal::skin_frame(&skin.bind, &skin.influences, &transforms(bones, pose, heading), out);
    if let Some(h) = pose.ground {
        let low = out.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
        for p in out.iter_mut() {
            p[1] += h - low;
        }
    }
}

/// Clip `index` of a rigged dataset: template, action, proportions and manner drawn from stream `index` of
/// `cfg.seed`.
pub(super) fn generate_one(cfg: &SynthConfig, kinds: RiggedKinds, index: usize) -> Result<Clip> {
    let mut r = rng(cfg.seed, index as u64);
    let able: Vec<Template> = Template::ALL
        .into_iter()
        .filter(|t| kinds.action.is_none_or(|a| t.actions().contains(&a)))
        .collect();
    let drawn = able[r.random_range(0..able.len())];
    let template = kinds.template.unwrap_or(drawn);
    let choices = template.actions();
    let drawn = choices[r.random_range(0..choices.len())];
    build(cfg, index, template, kinds.action.unwrap_or(drawn), &mut r)
}

/// Clip `index` with template and action forced (drawn otherwise as in [`generate_one`]), for the tests.
#[cfg(test)]
pub(super) fn generate_with(cfg: &SynthConfig, index: usize, template: Template, action: Action) -> Result<Clip> {
    let mut r = rng(cfg.seed, index as u64);
    let drawn = Template::ALL[r.random_range(0..Template::ALL.len())];
    let _action: usize = r.random_range(0..drawn.actions().len());
    build(cfg, index, template, action, &mut r)
}

fn build(cfg: &SynthConfig, index: usize, template: Template, action: Action, r: &mut DataRng) -> Result<Clip> {
    cfg.validate()?;
    let source = cfg.source(index);
    if !template.actions().contains(&action) {
        return Err(DataError::new(
            &source,
            "action",
            format!("a {} cannot {}", template.name(), action.name()),
        ));
    }
    let rig = skeletons::build(template, r);
    check_bones(&rig.bones).map_err(|e| e.at(&source))?;
    let target = r.random_range(cfg.min_vertices..=cfg.max_vertices);
    let skin = skin(&rig, target, cfg.min_vertices, cfg.max_vertices).map_err(|e| e.at(&source))?;
    let motion = actions::draw(action, &rig, r);
    let heading = f64::from(r.random_range(0.0f32..360.0));
    let n = skin.pos.len();
    let mut vertices = Vec::with_capacity(cfg.frames * n);
    let mut frame = Vec::with_capacity(n);
    for f in 0..cfg.frames {
        let tau = f as f32 / (cfg.frames - 1) as f32;
        let pose = actions::pose(&motion, &rig, tau);
        pose_frame(&skin, &rig.bones, &pose, heading, &mut frame);
        vertices.extend_from_slice(&frame);
    }
    let travel = {
        let (a, b) = (centroid(&vertices[..n]), centroid(&vertices[(cfg.frames - 1) * n..]));
        [b[0] - a[0], b[2] - a[2]]
    };
    let id = format!(
        "rigged-{}-{}-{}-{index}_offset0_0-{}",
        template.name(),
        action.name(),
        cfg.seed,
        cfg.frames - 1
    );
    let caption = caption::caption(&rig, &motion, travel);
    Clip::new(id, vertices, cfg.frames, n, skin.faces, caption, source)
}

fn centroid(frame: &[V3]) -> [f32; 3] {
    let k = 1.0 / frame.len().max(1) as f32;
    [0, 1, 2].map(|i| frame.iter().map(|p| p[i]).sum::<f32>() * k)
}

/// Template and action of a rigged clip id (`rigged-<template>-<action>-<seed>-<index>…`).
pub fn kinds(clip_id: &str) -> Option<(Template, Action)> {
    let mut parts = clip_id.strip_prefix("rigged-")?.split('-');
    let (t, a) = (parts.next()?, parts.next()?);
    Some((Template::from_name(t)?, Action::from_name(a)?))
}

#[cfg(test)]
mod tests;
