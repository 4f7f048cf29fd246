//! glTF 2.0 / GLB clips (SPEC §2.1): animation baked to per-frame world-space vertex positions, and a writer that
//! stores a clip as frame-0 mesh + one morph target per frame.
//!
//! Reading takes the first animation and the first triangle primitive of the chosen mesh, samples every channel
//! (STEP, LINEAR with slerp for rotations, CUBICSPLINE) at `t = f / fps` for `f = 0..=⌊duration · fps⌋`, and bakes
//! morph targets (`p = base + Σ_k w_k · target_k`), then skinning (`v = Σ_i w_i · G(joint_i) · IBM_i · p`) or, for
//! an unskinned mesh, the mesh node's world matrix. The caption is `asset.extras.caption` (written by
//! [`write_gltf`]), else " ".

use std::path::Path;

use gltf::animation::{Interpolation, Property, util::ReadOutputs};
use gltf::mesh::Mode;
use serde_json::json;

use super::dymesh_bin::{MISSING_CAPTION, write_atomic};
use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Frame rate used when none is given.
pub const DEFAULT_FPS: f32 = 30.0;

/// How to bake a glTF animation into frames.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfReadOptions {
    /// Sampling rate in frames per second.
    pub fps: f32,
    /// Keep at most this many frames.
    pub max_frames: Option<usize>,
    /// Mesh index to read; `None` = the first mesh that a node instantiates.
    pub mesh: Option<usize>,
}

impl Default for GltfReadOptions {
    fn default() -> Self {
        Self {
            fps: DEFAULT_FPS,
            max_frames: None,
            mesh: None,
        }
    }
}

type Mat = [[f64; 4]; 4]; // column-major, m[col][row], as glTF stores it

const IDENTITY: Mat = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

fn mul(a: &Mat, b: &Mat) -> Mat {
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, x) in col.iter_mut().enumerate() {
            *x = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

fn apply(m: &Mat, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

fn to_f64<const N: usize>(v: [f32; N]) -> [f64; N] {
    v.map(f64::from)
}

/// Local matrix T · R · S from translation, unit quaternion (x, y, z, w) and scale.
fn trs(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> Mat {
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

/// One animation channel: key times and `width` components per key (3 × for CUBICSPLINE: in-tangent, value,
/// out-tangent).
struct Track {
    node: usize,
    property: Property,
    interpolation: Interpolation,
    times: Vec<f32>,
    values: Vec<f64>,
    width: usize,
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
            Interpolation::Linear if self.property == Property::Rotation => slerp(a, b, u),
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

fn slerp(a: &[f64], b: &[f64], u: f64) -> Vec<f64> {
    let mut dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let sign = if dot < 0.0 { -1.0 } else { 1.0 };
    dot *= sign;
    let (wa, wb) = if dot > 0.9995 {
        (1.0 - u, u)
    } else {
        let theta = dot.acos();
        (
            (((1.0 - u) * theta).sin()) / theta.sin(),
            (u * theta).sin() / theta.sin(),
        )
    };
    a.iter().zip(b).map(|(x, y)| wa * x + wb * sign * y).collect()
}

/// Read and bake a `.gltf` / `.glb` clip. Errors name the file and the glTF part (field) at fault.
pub fn read_gltf(path: &Path, opts: &GltfReadOptions) -> Result<Clip> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let source = path.display().to_string();
    let err = |field: &str, reason: String| DataError::new(path, field, reason);
    if !(opts.fps.is_finite() && opts.fps > 0.0) {
        return Err(err("fps", format!("{} is not a positive frame rate", opts.fps)));
    }
    let gltf::Gltf { document: doc, blob } = gltf::Gltf::from_slice(&bytes).map_err(|e| err("gltf", e.to_string()))?;
    let buffers = gltf::import_buffers(&doc, path.parent(), blob).map_err(|e| err("buffers", e.to_string()))?;
    let data = |b: gltf::Buffer| Some(&buffers[b.index()].0[..]);

    let anim = doc
        .animations()
        .next()
        .ok_or_else(|| err("animations", "no animation".into()))?;
    let node = doc
        .nodes()
        .find(|n| n.mesh().is_some_and(|m| opts.mesh.is_none_or(|i| m.index() == i)))
        .ok_or_else(|| match opts.mesh {
            Some(i) => err("meshes", format!("no node instantiates mesh {i}")),
            None => err("meshes", "no node has a mesh".into()),
        })?;
    let mesh = node.mesh().expect("found by mesh");
    let mesh_field = format!("meshes[{}]", mesh.index());
    let prim = mesh
        .primitives()
        .find(|p| p.mode() == Mode::Triangles)
        .ok_or_else(|| err(&mesh_field, "no primitive with triangles".into()))?;
    let reader = prim.reader(data);
    let base: Vec<[f64; 3]> = reader
        .read_positions()
        .ok_or_else(|| err(&mesh_field, "primitive has no POSITION".into()))?
        .map(to_f64)
        .collect();
    let n = base.len();
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(err(
            &mesh_field,
            format!("{} indices is not a multiple of 3", indices.len()),
        ));
    }
    let faces: Vec<[u32; 3]> = indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let targets: Vec<Vec<[f64; 3]>> = reader
        .read_morph_targets()
        .map(|(p, _, _)| p.map_or_else(|| vec![[0.0; 3]; n], |p| p.map(to_f64).collect()))
        .collect();
    if let Some(k) = targets.iter().position(|t| t.len() != n) {
        return Err(err(
            &mesh_field,
            format!("morph target {k} has {} positions, base has {n}", targets[k].len()),
        ));
    }

    // Skin: per-vertex (joint, weight) influences over all JOINTS_i / WEIGHTS_i sets.
    let skin = node.skin();
    let mut influences: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let (joints, ibms): (Vec<usize>, Vec<Mat>) = match &skin {
        None => (Vec::new(), Vec::new()),
        Some(s) => {
            let joints: Vec<usize> = s.joints().map(|j| j.index()).collect();
            let ibms: Vec<Mat> = match s.reader(data).read_inverse_bind_matrices() {
                Some(m) => m.map(|m| m.map(to_f64)).collect(),
                None => vec![IDENTITY; joints.len()],
            };
            if ibms.len() != joints.len() {
                return Err(err(
                    "skins",
                    format!("{} inverse bind matrices for {} joints", ibms.len(), joints.len()),
                ));
            }
            let mut set = 0;
            while let (Some(j), Some(w)) = (reader.read_joints(set), reader.read_weights(set)) {
                for (v, (j, w)) in j.into_u16().zip(w.into_f32()).enumerate().take(n) {
                    for (ji, wi) in j.into_iter().zip(w) {
                        if wi != 0.0 {
                            if ji as usize >= joints.len() {
                                return Err(err(
                                    &format!("JOINTS_{set}"),
                                    format!("vertex {v} uses joint {ji} of {}", joints.len()),
                                ));
                            }
                            influences[v].push((ji as usize, wi as f64));
                        }
                    }
                }
                set += 1;
            }
            if set == 0 {
                return Err(err(&mesh_field, "skinned node without JOINTS_0/WEIGHTS_0".into()));
            }
            if let Some(v) = influences.iter().position(|i| i.is_empty()) {
                return Err(err("WEIGHTS_0", format!("vertex {v} has no joint weight")));
            }
            (joints, ibms)
        }
    };

    // Animation tracks.
    let mut tracks = Vec::new();
    for ch in anim.channels() {
        let field = format!("animations[{}].channels[{}]", anim.index(), ch.index());
        let r = ch.reader(data);
        let times: Vec<f32> = r
            .read_inputs()
            .ok_or_else(|| err(&field, "no input times".into()))?
            .collect();
        let (values, width): (Vec<f64>, usize) =
            match r.read_outputs().ok_or_else(|| err(&field, "no outputs".into()))? {
                ReadOutputs::Translations(o) | ReadOutputs::Scales(o) => (o.flat_map(to_f64).collect(), 3),
                ReadOutputs::Rotations(o) => (o.into_f32().flat_map(to_f64).collect(), 4),
                ReadOutputs::MorphTargetWeights(o) => (o.into_f32().map(f64::from).collect(), targets.len().max(1)),
            };
        let interpolation = ch.sampler().interpolation();
        let per_key = if interpolation == Interpolation::CubicSpline {
            3 * width
        } else {
            width
        };
        if times.is_empty() || values.len() != times.len() * per_key {
            return Err(err(
                &field,
                format!(
                    "{} keys but {} output values ({per_key} per key expected)",
                    times.len(),
                    values.len()
                ),
            ));
        }
        if times.windows(2).any(|w| w[1] < w[0]) || !times.iter().all(|t| t.is_finite()) {
            return Err(err(&field, "key times are not increasing".into()));
        }
        tracks.push(Track {
            node: ch.target().node().index(),
            property: ch.target().property(),
            interpolation,
            times,
            values,
            width,
        });
    }
    let duration = tracks.iter().map(|t| t.times[t.times.len() - 1]).fold(0.0f32, f32::max);
    let mut frames = (duration as f64 * opts.fps as f64 + 1e-4).floor() as usize + 1;
    if let Some(m) = opts.max_frames {
        frames = frames.min(m);
    }

    // Node hierarchy: parents, rest TRS, and whether a node is animated (then its TRS is used, else its matrix).
    let count = doc.nodes().len();
    let mut parent = vec![None; count];
    for p in doc.nodes() {
        for c in p.children() {
            parent[c.index()] = Some(p.index());
        }
    }
    let rest: Vec<([f64; 3], [f64; 4], [f64; 3])> = doc
        .nodes()
        .map(|nd| nd.transform().decomposed())
        .map(|(t, r, s)| (to_f64(t), to_f64(r), to_f64(s)))
        .collect();
    let rest_matrix: Vec<Mat> = doc.nodes().map(|nd| nd.transform().matrix().map(to_f64)).collect();
    let default_weights: Vec<f64> = node
        .weights()
        .or(mesh.weights())
        .map_or_else(|| vec![0.0; targets.len()], |w| w.iter().map(|&x| x as f64).collect());
    if default_weights.len() != targets.len() {
        return Err(err(
            &mesh_field,
            format!(
                "{} default weights for {} morph targets",
                default_weights.len(),
                targets.len()
            ),
        ));
    }

    let mut vertices = Vec::with_capacity(frames * n);
    for f in 0..frames {
        let t = f as f32 / opts.fps;
        let mut pose = rest.clone();
        let mut animated = vec![false; count];
        let mut weights = default_weights.clone();
        for tr in &tracks {
            let v = tr.sample(t);
            animated[tr.node] = true;
            let p = &mut pose[tr.node];
            match tr.property {
                Property::Translation => p.0 = [v[0], v[1], v[2]],
                Property::Rotation => p.1 = [v[0], v[1], v[2], v[3]],
                Property::Scale => p.2 = [v[0], v[1], v[2]],
                Property::MorphTargetWeights if tr.node == node.index() => weights = v,
                Property::MorphTargetWeights => {}
            }
        }
        let mut global: Vec<Option<Mat>> = vec![None; count];
        let mut world = |i: usize| -> Mat {
            let mut chain = vec![i];
            while let Some(p) = parent[*chain.last().expect("non-empty")] {
                if global[p].is_some() || chain.len() > count {
                    break;
                }
                chain.push(p);
            }
            for &k in chain.iter().rev() {
                let local = if animated[k] {
                    trs(pose[k].0, pose[k].1, pose[k].2)
                } else {
                    rest_matrix[k]
                };
                global[k] = Some(match parent[k].and_then(|p| global[p]) {
                    Some(pm) => mul(&pm, &local),
                    None => local,
                });
            }
            global[i].expect("computed")
        };
        // (morph) p = base + Σ_k w_k · target_k
        let morphed = base.iter().enumerate().map(|(v, b)| {
            let mut p = *b;
            for (w, tgt) in weights.iter().zip(&targets) {
                for c in 0..3 {
                    p[c] += w * tgt[v][c];
                }
            }
            p
        });
        if skin.is_some() {
            // (skin) v = Σ_i w_i · G(joint_i) · IBM_i · p, weights normalised to sum 1
            let skin_mats: Vec<Mat> = joints.iter().zip(&ibms).map(|(&j, ibm)| mul(&world(j), ibm)).collect();
            for (p, inf) in morphed.zip(&influences) {
                let total: f64 = inf.iter().map(|(_, w)| w).sum();
                let mut out = [0.0; 3];
                for &(j, w) in inf {
                    let q = apply(&skin_mats[j], p);
                    (0..3).for_each(|c| out[c] += w / total * q[c]);
                }
                vertices.push(out.map(|x| x as f32));
            }
        } else {
            let m = world(node.index());
            vertices.extend(morphed.map(|p| apply(&m, p).map(|x| x as f32)));
        }
    }

    let caption = caption_of(&bytes).unwrap_or_else(|| MISSING_CAPTION.to_string());
    let id = path
        .file_stem()
        .map_or_else(|| source.clone(), |s| s.to_string_lossy().into_owned());
    Clip::new(id, vertices, frames, n, faces, caption, source)
}

/// `asset.extras.caption` of a `.gltf` or `.glb`, read from the raw JSON (the gltf crate drops extras).
fn caption_of(bytes: &[u8]) -> Option<String> {
    let json_bytes = match gltf::Glb::from_slice(bytes) {
        Ok(glb) => glb.json.into_owned(),
        Err(_) => bytes.to_vec(),
    };
    let v: serde_json::Value = serde_json::from_slice(&json_bytes).ok()?;
    v.get("asset")?
        .get("extras")?
        .get("caption")?
        .as_str()
        .map(str::to_string)
}

/// Write `clip` as `.gltf` (embedded base64 buffer) or `.glb` (by extension): the frame-0 mesh as base, one morph
/// target per frame (`frame_f − frame_0`) and a STEP weights animation whose key `f` at `f / fps` seconds is the
/// one-hot vector of target `f`, so frame `f` shows exactly target `f`. The caption goes to `asset.extras.caption`.
pub fn write_gltf(path: &Path, clip: &Clip, fps: f32) -> Result<()> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DataError::new(
            path,
            "fps",
            format!("{fps} is not a positive frame rate"),
        ));
    }
    let binary = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let t = clip.frames;
    let mut buf: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut push = |bytes: Vec<u8>, accessor: serde_json::Value| -> usize {
        views.push(json!({"buffer": 0, "byteOffset": buf.len(), "byteLength": bytes.len()}));
        buf.extend(bytes);
        while !buf.len().is_multiple_of(4) {
            buf.push(0);
        }
        let mut a = accessor;
        a["bufferView"] = json!(views.len() - 1);
        accessors.push(a);
        accessors.len() - 1
    };
    let vec3 = |rows: &[[f32; 3]]| {
        let lo: Vec<f32> = (0..3)
            .map(|c| rows.iter().map(|r| r[c]).fold(f32::INFINITY, f32::min))
            .collect();
        let hi: Vec<f32> = (0..3)
            .map(|c| rows.iter().map(|r| r[c]).fold(f32::NEG_INFINITY, f32::max))
            .collect();
        let bytes = rows.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        (
            bytes,
            json!({"componentType": 5126, "count": rows.len(), "type": "VEC3", "min": lo, "max": hi}),
        )
    };
    let (b, a) = vec3(clip.frame(0));
    let position = push(b, a);
    let idx: Vec<u8> = clip.faces.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
    let indices = push(
        idx,
        json!({"componentType": 5125, "count": clip.faces.len() * 3, "type": "SCALAR"}),
    );
    let mut targets = Vec::with_capacity(t);
    for f in 0..t {
        let d: Vec<[f32; 3]> = clip
            .frame(f)
            .iter()
            .zip(clip.frame(0))
            .map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]])
            .collect();
        let (b, a) = vec3(&d);
        targets.push(json!({"POSITION": push(b, a)}));
    }
    let times: Vec<f32> = (0..t).map(|f| f as f32 / fps).collect();
    let times_acc = push(
        times.iter().flat_map(|x| x.to_le_bytes()).collect(),
        json!({"componentType": 5126, "count": t, "type": "SCALAR", "min": [times[0]], "max": [times[t - 1]]}),
    );
    let onehot: Vec<u8> = (0..t * t)
        .flat_map(|i| if i / t == i % t { 1.0f32 } else { 0.0 }.to_le_bytes())
        .collect();
    let weights_acc = push(onehot, json!({"componentType": 5126, "count": t * t, "type": "SCALAR"}));
    let mut buffer = json!({"byteLength": buf.len()});
    if !binary {
        buffer["uri"] = json!(format!("data:application/octet-stream;base64,{}", base64(&buf)));
    }
    let names: Vec<String> = (0..t).map(|f| format!("frame_{f:04}")).collect();
    let doc = json!({
        "asset": {"version": "2.0", "generator": "any4d", "extras": {"caption": clip.caption, "id": clip.id}},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": clip.id}],
        "meshes": [{
            "name": clip.id,
            "primitives": [{"attributes": {"POSITION": position}, "indices": indices, "mode": 4, "targets": targets}],
            "weights": vec![0.0; t],
            "extras": {"targetNames": names},
        }],
        "animations": [{
            "name": "frames",
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
            "samplers": [{"input": times_acc, "output": weights_acc, "interpolation": "STEP"}],
        }],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [buffer],
    });
    let text = serde_json::to_vec(&doc).map_err(|e| DataError::new(path, "gltf", e.to_string()))?;
    let bytes = if binary { glb(text, buf) } else { text };
    write_atomic(path, &bytes)
}

/// GLB container: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded).
fn glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

/// Standard base64 with padding.
fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let w = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(w >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
        ];
        for (raw, enc) in cases {
            assert_eq!(base64(raw.as_bytes()), enc);
        }
    }

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
    fn slerp_halfway_is_45_degrees() {
        let s = 0.5f64.sqrt();
        let q = slerp(&[0.0, 0.0, 0.0, 1.0], &[0.0, 0.0, s, s], 0.5);
        let half = (std::f64::consts::PI / 8.0).sin();
        assert!((q[2] - half).abs() < 1e-12, "{q:?}");
    }
}
