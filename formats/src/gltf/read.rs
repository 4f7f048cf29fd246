//! From a loaded glTF document to a clip: pick the mesh node and primitive, read and check every accessor, node,
//! skin and channel it uses, bound the frame count, then bake.

use std::path::Path;

use gltf::json::accessor::Type;
use gltf::json::animation::{Interpolation as JsonInterpolation, Property as JsonProperty};
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::Checked;
use gltf::json::{self, Root};

use super::accessor::{self, FLOAT, FLOAT_OR_NORMALIZED, INDICES, JOINTS, WEIGHTS};
use super::bake::{self, IDENTITY, Interpolation, Mat, Property, RestNode, Scene, Skin, Track};
use super::source::{self, Document};
use super::{Ctx, ExternalBuffers, GltfReadOptions};
use crate::clip::Clip;
use crate::dymesh_bin::MISSING_CAPTION;
use crate::error::Result;
use crate::limits::{CLIP_VERTICES, FRAMES};
use crate::skeletal::TakeInfo;

/// The takes of a glTF file, each a name and the animations baked together: one take of every animation when no
/// two target the same channel (node and property) — exporters such as COLLADA2GLTF write one animation per
/// joint, which players run together — else one take per animation (Blender writes one per action), named after
/// it (`animation<a>` when it has no name).
pub(super) fn take_groups(animations: &[json::Animation]) -> Vec<(String, Vec<usize>)> {
    let named = |a: usize| {
        animations[a]
            .name
            .clone()
            .filter(|n| !n.trim().is_empty())
            .unwrap_or_else(|| format!("animation{a}"))
    };
    let mut owner = std::collections::HashMap::new();
    let disjoint = animations.iter().enumerate().all(|(a, anim)| {
        anim.channels.iter().all(|ch| {
            let key = (ch.target.node.value(), format!("{:?}", ch.target.path));
            *owner.entry(key).or_insert(a) == a
        })
    });
    match animations.len() {
        0 => Vec::new(),
        1 => vec![(named(0), vec![0])],
        n if disjoint => vec![("all".to_owned(), (0..n).collect())],
        n => (0..n).map(|a| (named(a), vec![a])).collect(),
    }
}

/// The takes of one glTF / GLB file's bytes ([`take_groups`]), each as long as its latest key, in frames at
/// `fps`; the key times are read and checked as the bake reads them.
pub(super) fn takes(bytes: &[u8], path: &Path, fps: f32, external: &ExternalBuffers) -> Result<Vec<TakeInfo>> {
    let ctx = Ctx { path };
    let doc = source::load(ctx, bytes, external)?;
    let (r, root) = (Reader::of(ctx, &doc), &doc.root);
    let mut out = Vec::new();
    for (name, group) in take_groups(&root.animations) {
        let mut duration = 0.0f64;
        for &a in &group {
            for (c, ch) in root.animations[a].channels.iter().enumerate() {
                let field = format!("animations[{a}].channels[{c}]");
                let s = ch.sampler.value();
                let sampler = root.animations[a]
                    .samplers
                    .get(s)
                    .ok_or_else(|| ctx.err(format!("{field}.sampler"), format!("sampler {s} does not exist")))?;
                let times = r.floats(sampler.input.value(), &format!("{field} input"), Type::Scalar, FLOAT)?;
                if !times.iter().all(|t| t.is_finite()) || times.windows(2).any(|w| w[1] < w[0]) {
                    return Err(ctx.err(&field, "key times are not increasing"));
                }
                duration = duration.max(times.last().copied().unwrap_or(0.0));
            }
        }
        out.push(TakeInfo {
            name,
            // A float-to-int cast saturates: a take longer than any limit stays longer than it.
            frames: (duration * f64::from(fps) + 1e-4).floor() as usize + 1,
            fps,
            file: None,
        });
    }
    Ok(out)
}

/// Read and bake one glTF / GLB file's bytes.
pub(super) fn read(bytes: &[u8], path: &Path, opts: &GltfReadOptions, external: &ExternalBuffers) -> Result<Clip> {
    let ctx = Ctx { path };
    if !(opts.fps.is_finite() && opts.fps > 0.0) {
        return Err(ctx.err("fps", format!("{} is not a positive frame rate", opts.fps)));
    }
    let doc = source::load(ctx, bytes, external)?;
    let (r, root, caption) = (Reader::of(ctx, &doc), &doc.root, doc.caption.clone());
    if root.animations.is_empty() {
        return Err(ctx.err("animations", "no animation"));
    }
    let node_index = root
        .nodes
        .iter()
        .position(|n| n.mesh.is_some_and(|m| opts.mesh.is_none_or(|i| m.value() == i)))
        .ok_or_else(|| match opts.mesh {
            Some(i) => ctx.err("meshes", format!("no node instantiates mesh {i}")),
            None => ctx.err("meshes", "no node has a mesh"),
        })?;
    let node = &root.nodes[node_index];
    let mesh_index = node.mesh.expect("found by mesh").value();
    let mesh_field = format!("meshes[{mesh_index}]");
    let mesh = root.meshes.get(mesh_index).ok_or_else(|| {
        ctx.err(
            format!("nodes[{node_index}].mesh"),
            format!("mesh {mesh_index} does not exist"),
        )
    })?;
    let prim = mesh
        .primitives
        .iter()
        .find(|p| p.mode == Checked::Valid(Mode::Triangles))
        .ok_or_else(|| ctx.err(&mesh_field, "no primitive with triangles"))?;
    let position = prim
        .attributes
        .get(&Checked::Valid(Semantic::Positions))
        .ok_or_else(|| ctx.err(&mesh_field, "primitive has no POSITION"))?;
    let base = rows3(&r.floats(position.value(), &format!("{mesh_field} POSITION"), Type::Vec3, FLOAT)?);
    let n = base.len();
    let indices = match prim.indices {
        Some(i) => r.u32s(i.value(), &format!("{mesh_field} indices"), Type::Scalar, INDICES)?,
        None => (0..u32::try_from(n).map_err(|_| ctx.err(&mesh_field, "too many vertices"))?).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(ctx.err(&mesh_field, format!("{} indices is not a multiple of 3", indices.len())));
    }
    let faces: Vec<[u32; 3]> = indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let mut targets = Vec::new();
    for (k, t) in prim.targets.iter().flatten().enumerate() {
        let field = format!("{mesh_field} morph target {k} POSITION");
        let rows = match t.positions {
            Some(p) => rows3(&r.floats(p.value(), &field, Type::Vec3, FLOAT)?),
            None => vec![[0.0; 3]; n],
        };
        if rows.len() != n {
            return Err(ctx.err(field, format!("{} positions, the base has {n}", rows.len())));
        }
        targets.push(rows);
    }
    let default_weights: Vec<f64> = node
        .weights
        .as_ref()
        .or(mesh.weights.as_ref())
        .map_or_else(|| vec![0.0; targets.len()], |w| w.iter().map(|&x| x as f64).collect());
    if default_weights.len() != targets.len() {
        return Err(ctx.err(
            &mesh_field,
            format!(
                "{} default weights for {} morph targets",
                default_weights.len(),
                targets.len()
            ),
        ));
    }
    let skin = match node.skin {
        None => None,
        Some(s) => Some(r.skin(s.value(), prim, n, &mesh_field)?),
    };
    let nodes = r.hierarchy()?;
    let mut tracks = Vec::new();
    let groups = take_groups(&root.animations);
    let (_, group) = groups.get(opts.take).ok_or_else(|| {
        ctx.err(
            "animations",
            format!("take {} of a file with {} takes", opts.take, groups.len()),
        )
    })?;
    for &a in group {
        tracks.extend(r.tracks(a, &root.animations[a], node_index, targets.len())?);
    }

    let duration = tracks.iter().map(|t| t.times[t.times.len() - 1]).fold(0.0f32, f32::max);
    let wanted = (duration as f64 * opts.fps as f64 + 1e-4).floor() + 1.0;
    let (max_frames, max_rows) = (FRAMES.get_usize(), CLIP_VERTICES.get_usize());
    let frames = match opts.max_frames {
        Some(m) => wanted.min(m as f64) as usize,
        None if wanted > max_frames as f64 => {
            return Err(ctx.err(
                "animations",
                format!(
                    "lasts {duration} s = {wanted} frames at {} fps, more than the limit of {max_frames} frames{} \
                     (read options `max_frames` keep the first frames of a longer animation)",
                    opts.fps,
                    FRAMES.hint()
                ),
            ));
        }
        None => wanted as usize,
    };
    if frames.checked_mul(n).is_none_or(|rows| rows > max_rows) {
        return Err(ctx.err(
            &mesh_field,
            format!(
                "{frames} frames × {n} vertices is more than the limit of {max_rows} baked vertices{}",
                CLIP_VERTICES.hint()
            ),
        ));
    }
    let scene = Scene {
        nodes,
        mesh_node: node_index,
        base,
        targets,
        default_weights,
        skin,
        tracks,
    };
    let vertices = bake::bake(ctx, &scene, frames, opts.fps)?;
    let source = path.display().to_string();
    let id = path
        .file_stem()
        .map_or_else(|| source.clone(), |s| s.to_string_lossy().into_owned());
    let caption = caption.unwrap_or_else(|| MISSING_CAPTION.to_string());
    Clip::new(id, vertices, frames, n, faces, caption, source)
}

pub(super) fn rows3(flat: &[f64]) -> Vec<[f64; 3]> {
    flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

pub(super) struct Reader<'a> {
    ctx: Ctx<'a>,
    root: &'a Root,
    buffers: &'a [Vec<u8>],
}

impl<'a> Reader<'a> {
    /// A reader over a loaded document.
    pub(super) fn of(ctx: Ctx<'a>, doc: &'a Document) -> Self {
        Reader {
            ctx,
            root: &doc.root,
            buffers: &doc.buffers,
        }
    }

    pub(super) fn floats(&self, index: usize, field: &str, ty: Type, allowed: &[accessor::Form]) -> Result<Vec<f64>> {
        accessor::read(self.ctx, self.root, self.buffers, index, field, ty, allowed)
    }

    pub(super) fn u32s(&self, index: usize, field: &str, ty: Type, allowed: &[accessor::Form]) -> Result<Vec<u32>> {
        accessor::read_u32(self.ctx, self.root, self.buffers, index, field, ty, allowed)
    }

    /// Skin `s` of the mesh node: joints, inverse bind matrices and the influences of all JOINTS_i / WEIGHTS_i sets.
    fn skin(&self, s: usize, prim: &json::mesh::Primitive, n: usize, mesh_field: &str) -> Result<Skin> {
        let field = format!("skins[{s}]");
        let skin = self
            .root
            .skins
            .get(s)
            .ok_or_else(|| self.ctx.err(&field, "the skin does not exist"))?;
        let joints: Vec<usize> = skin.joints.iter().map(|j| j.value()).collect();
        if let Some(j) = joints.iter().find(|&&j| j >= self.root.nodes.len()) {
            return Err(self.ctx.err(&field, format!("joint node {j} does not exist")));
        }
        let ibms: Vec<Mat> = match skin.inverse_bind_matrices {
            Some(a) => self
                .floats(a.value(), &format!("{field} inverseBindMatrices"), Type::Mat4, FLOAT)?
                .chunks_exact(16)
                .map(|m| std::array::from_fn(|c| std::array::from_fn(|r| m[4 * c + r])))
                .collect(),
            None => vec![IDENTITY; joints.len()],
        };
        if ibms.len() != joints.len() {
            return Err(self.ctx.err(
                &field,
                format!("{} inverse bind matrices for {} joints", ibms.len(), joints.len()),
            ));
        }
        let mut influences: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        let mut first_joint: Vec<u32> = Vec::new();
        let mut set = 0;
        loop {
            let attr = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|i| i.value());
            let (j, w) = match (attr(Semantic::Joints(set)), attr(Semantic::Weights(set))) {
                (Some(j), Some(w)) => (j, w),
                (None, None) => break,
                _ => {
                    return Err(self
                        .ctx
                        .err(mesh_field, format!("JOINTS_{set} and WEIGHTS_{set} must come together")));
                }
            };
            let jf = format!("{mesh_field} JOINTS_{set}");
            let j = self.u32s(j, &jf, Type::Vec4, JOINTS)?;
            let w = self.floats(w, &format!("{mesh_field} WEIGHTS_{set}"), Type::Vec4, WEIGHTS)?;
            if j.len() != 4 * n || w.len() != 4 * n {
                return Err(self.ctx.err(
                    &jf,
                    format!("{} joints and {} weights for {n} vertices", j.len() / 4, w.len() / 4),
                ));
            }
            if set == 0 {
                first_joint = j.chunks_exact(4).map(|js| js[0]).collect();
            }
            for (v, (js, ws)) in j.chunks_exact(4).zip(w.chunks_exact(4)).enumerate() {
                for (&ji, &wi) in js.iter().zip(ws) {
                    if !(wi.is_finite() && wi >= 0.0) {
                        return Err(self.ctx.err(&jf, format!("vertex {v} has joint weight {wi}")));
                    }
                    if wi != 0.0 {
                        if ji as usize >= joints.len() {
                            return Err(self
                                .ctx
                                .err(&jf, format!("vertex {v} uses joint {ji} of {}", joints.len())));
                        }
                        influences[v].push((ji as usize, wi));
                    }
                }
            }
            set += 1;
        }
        if set == 0 {
            return Err(self.ctx.err(mesh_field, "skinned node without JOINTS_0/WEIGHTS_0"));
        }
        // A vertex whose weights are all 0 follows the first joint of its JOINTS_0 entry, as three.js's loader
        // normalises it (exporters leave such vertices on meshes that are mostly skinned).
        for (v, list) in influences.iter_mut().enumerate().filter(|(_, l)| l.is_empty()) {
            let j = first_joint[v] as usize;
            if j >= joints.len() {
                return Err(self.ctx.err(
                    format!("{mesh_field} WEIGHTS_0"),
                    format!(
                        "vertex {v} has no joint weight and its first joint {j} is not one of {}",
                        joints.len()
                    ),
                ));
            }
            list.push((j, 1.0));
        }
        Ok(Skin {
            joints,
            ibms,
            influences,
        })
    }

    /// Every node's parent and rest transform; the parents must form a forest (one parent each, no cycle).
    pub(super) fn hierarchy(&self) -> Result<Vec<RestNode>> {
        let nodes = &self.root.nodes;
        let count = nodes.len();
        let mut parent: Vec<Option<usize>> = vec![None; count];
        for (p, node) in nodes.iter().enumerate() {
            for c in node.children.iter().flatten() {
                let c = c.value();
                let field = format!("nodes[{p}].children");
                if c >= count {
                    return Err(self.ctx.err(field, format!("node {c} does not exist")));
                }
                if let Some(q) = parent[c] {
                    return Err(self.ctx.err(field, format!("node {c} is also a child of node {q}")));
                }
                parent[c] = Some(p);
            }
        }
        for start in 0..count {
            let (mut at, mut steps) = (start, 0);
            while let Some(p) = parent[at] {
                steps += 1;
                if steps > count {
                    return Err(self
                        .ctx
                        .err(format!("nodes[{start}]"), "the node hierarchy has a cycle"));
                }
                at = p;
            }
        }
        Ok(nodes
            .iter()
            .zip(parent)
            .map(|(nd, parent)| {
                let f64s = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
                match nd.matrix {
                    Some(m) => {
                        let m = f64s(&m);
                        let matrix: Mat = std::array::from_fn(|c| std::array::from_fn(|r| m[4 * c + r]));
                        RestNode {
                            parent,
                            trs: bake::decompose(&matrix),
                            matrix,
                        }
                    }
                    None => {
                        let t = nd.translation.unwrap_or([0.0; 3]).map(f64::from);
                        let q = nd.rotation.unwrap_or_default().0.map(f64::from);
                        let s = nd.scale.unwrap_or([1.0; 3]).map(f64::from);
                        RestNode {
                            parent,
                            trs: (t, q, s),
                            matrix: bake::trs(t, q, s),
                        }
                    }
                }
            })
            .collect())
    }

    /// The channels of animation `a` that can move the mesh: TRS of any node, weights of the mesh node.
    fn tracks(&self, a: usize, anim: &json::Animation, mesh_node: usize, n_targets: usize) -> Result<Vec<Track>> {
        let mut tracks = Vec::new();
        for (c, ch) in anim.channels.iter().enumerate() {
            let field = format!("animations[{a}].channels[{c}]");
            let node = ch.target.node.value();
            if node >= self.root.nodes.len() {
                return Err(self
                    .ctx
                    .err(format!("{field}.target.node"), format!("node {node} does not exist")));
            }
            let Checked::Valid(path) = ch.target.path else {
                return Err(self.ctx.err(
                    format!("{field}.target.path"),
                    "not translation, rotation, scale or weights",
                ));
            };
            let (property, ty, forms, width) = match path {
                JsonProperty::Translation => (Property::Translation, Type::Vec3, FLOAT, 3),
                JsonProperty::Scale => (Property::Scale, Type::Vec3, FLOAT, 3),
                JsonProperty::Rotation => (Property::Rotation, Type::Vec4, FLOAT_OR_NORMALIZED, 4),
                // Weights of other nodes, or of a mesh without targets, cannot move this mesh.
                JsonProperty::MorphTargetWeights if node != mesh_node || n_targets == 0 => continue,
                JsonProperty::MorphTargetWeights => (Property::Weights, Type::Scalar, FLOAT_OR_NORMALIZED, n_targets),
            };
            let s = ch.sampler.value();
            let sampler = anim.samplers.get(s).ok_or_else(|| {
                self.ctx
                    .err(format!("{field}.sampler"), format!("sampler {s} does not exist"))
            })?;
            let interpolation = match sampler.interpolation {
                Checked::Valid(JsonInterpolation::Step) => Interpolation::Step,
                Checked::Valid(JsonInterpolation::Linear) => Interpolation::Linear,
                Checked::Valid(JsonInterpolation::CubicSpline) => Interpolation::CubicSpline,
                Checked::Invalid => {
                    return Err(self.ctx.err(
                        format!("animations[{a}].samplers[{s}].interpolation"),
                        "not STEP, LINEAR or CUBICSPLINE",
                    ));
                }
            };
            let times: Vec<f32> = self
                .floats(sampler.input.value(), &format!("{field} input"), Type::Scalar, FLOAT)?
                .into_iter()
                .map(|t| t as f32)
                .collect();
            let values = self.floats(sampler.output.value(), &format!("{field} output"), ty, forms)?;
            let per_key = if interpolation == Interpolation::CubicSpline {
                3 * width
            } else {
                width
            };
            if times.is_empty() || times.len().checked_mul(per_key) != Some(values.len()) {
                return Err(self.ctx.err(
                    &field,
                    format!(
                        "{} keys but {} output values ({per_key} per key expected)",
                        times.len(),
                        values.len()
                    ),
                ));
            }
            if times.windows(2).any(|w| w[1] < w[0]) || !times.iter().all(|t| t.is_finite()) {
                return Err(self.ctx.err(&field, "key times are not increasing"));
            }
            tracks.push(Track {
                node,
                property,
                interpolation,
                times,
                values,
                width,
            });
        }
        Ok(tracks)
    }
}
