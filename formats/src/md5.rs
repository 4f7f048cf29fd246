//! Doom 3 MD5 (`.md5mesh` + `.md5anim`, version 10, text): weighted-joint meshes baked per animation frame.
//!
//! The takes of a `.md5mesh` are the `.md5anim` files in its folder whose joint names and parents equal the
//! mesh's (in order), each named by its file stem. All meshes of the file are read into one vertex list. A vertex
//! is `Σ_k bias_k · (p_j + q_j · w_k · q_j⁻¹)` over its weights, with `(p_j, q_j)` the object-space joint of
//! the frame; the unit quaternions store x, y, z and `w = −√(1 − x² − y² − z²)`. Frames are the file's own;
//! coordinates go from Z-up to Y-up ([`super::skeletal::z_up_to_y_up`]). Nothing is allocated from a count the
//! file states: lists grow as their entries are parsed and must then match the stated counts.

use std::path::Path;

use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo, check_parents, quat_mul, quat_rotate, z_up_to_y_up};
use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Largest MD5 text file read, in bytes.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

struct Tokens<'a> {
    path: &'a Path,
    toks: Vec<&'a str>,
    at: usize,
}

impl<'a> Tokens<'a> {
    fn new(path: &'a Path, text: &'a str) -> Self {
        let mut toks = Vec::new();
        for line in text.lines() {
            let line = line.split("//").next().unwrap_or("");
            let mut rest = line;
            while let Some(start) = rest.find(|c: char| !c.is_whitespace()) {
                rest = &rest[start..];
                if let Some(body) = rest.strip_prefix('"') {
                    let end = body.find('"').unwrap_or(body.len());
                    toks.push(&body[..end]);
                    rest = body.get(end + 1..).unwrap_or("");
                } else if rest.starts_with(['(', ')', '{', '}']) {
                    toks.push(&rest[..1]);
                    rest = &rest[1..];
                } else {
                    let end = rest
                        .find(|c: char| c.is_whitespace() || "(){}\"".contains(c))
                        .unwrap_or(rest.len());
                    toks.push(&rest[..end]);
                    rest = &rest[end..];
                }
            }
        }
        Self { path, toks, at: 0 }
    }

    fn err(&self, field: &str, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }

    fn next(&mut self, field: &str) -> Result<&'a str> {
        let t = self
            .toks
            .get(self.at)
            .ok_or_else(|| self.err(field, "the file ends early"))?;
        self.at += 1;
        Ok(t)
    }

    fn expect(&mut self, want: &str, field: &str) -> Result<()> {
        let t = self.next(field)?;
        if t != want {
            return Err(self.err(field, format!("expected `{want}`, found `{t}`")));
        }
        Ok(())
    }

    fn num<T: std::str::FromStr>(&mut self, field: &str) -> Result<T> {
        let t = self.next(field)?;
        t.parse()
            .map_err(|_| self.err(field, format!("`{t}` is not a number of the expected kind")))
    }

    fn float(&mut self, field: &str) -> Result<f64> {
        let v: f64 = self.num(field)?;
        if !v.is_finite() {
            return Err(self.err(field, format!("non-finite value {v}")));
        }
        Ok(v)
    }

    fn vec3(&mut self, field: &str) -> Result<[f64; 3]> {
        self.expect("(", field)?;
        let v = [self.float(field)?, self.float(field)?, self.float(field)?];
        self.expect(")", field)?;
        Ok(v)
    }

    /// `key value`, e.g. `numJoints 27`.
    fn keyed<T: std::str::FromStr>(&mut self, key: &str) -> Result<T> {
        self.expect(key, key)?;
        self.num(key)
    }

    fn done(&self) -> bool {
        self.at >= self.toks.len()
    }
}

/// A unit quaternion from the stored x, y, z (w ≤ 0).
fn quat(v: [f64; 3]) -> [f64; 4] {
    let t = 1.0 - v[0] * v[0] - v[1] * v[1] - v[2] * v[2];
    [v[0], v[1], v[2], if t < 0.0 { 0.0 } else { -t.sqrt() }]
}

fn read_text(path: &Path) -> Result<String> {
    super::read_text_file(path, MAX_TEXT_BYTES.min(crate::limits::FILE_BYTES.get()))
}

/// `MD5Version 10` and the `commandline` string, each optional: Red Eclipse ships meshes without one or both
/// lines, and its engine reads them. A version other than 10 is refused.
fn header(t: &mut Tokens) -> Result<()> {
    if t.toks.get(t.at) == Some(&"MD5Version") {
        let version: u32 = t.keyed("MD5Version")?;
        if version != 10 {
            return Err(t.err("MD5Version", format!("version {version}, only 10 is supported")));
        }
    }
    if t.toks.get(t.at) == Some(&"commandline") {
        t.next("commandline")?;
        t.next("commandline")?;
    }
    Ok(())
}

/// A bind-pose joint: only its name and parent are used (the weights' positions are joint-local, so the bind
/// transforms are not needed to bake a frame).
struct Joint {
    name: String,
    parent: i32,
}

#[derive(Clone, Copy)]
struct Weight {
    joint: usize,
    bias: f64,
    pos: [f64; 3],
}

struct Mesh {
    joints: Vec<Joint>,
    /// Per vertex: its weights.
    verts: Vec<Vec<Weight>>,
    faces: Vec<[u32; 3]>,
}

fn parse_mesh(path: &Path) -> Result<Mesh> {
    let text = read_text(path)?;
    let mut t = Tokens::new(path, &text);
    header(&mut t)?;
    let num_joints: usize = t.keyed("numJoints")?;
    let num_meshes: usize = t.keyed("numMeshes")?;
    if num_joints > skeletal::MAX_JOINTS {
        return Err(t.err(
            "numJoints",
            format!("{num_joints} joints, more than {}", skeletal::MAX_JOINTS),
        ));
    }
    t.expect("joints", "joints")?;
    t.expect("{", "joints")?;
    let mut joints = Vec::new();
    for j in 0..num_joints {
        let f = format!("joints[{j}]");
        let name = t.next(&f)?.to_owned();
        let parent: i32 = t.num(&f)?;
        t.vec3(&f)?; // bind position
        t.vec3(&f)?; // bind rotation
        joints.push(Joint { name, parent });
    }
    t.expect("}", "joints")?;
    check_parents(path, "joints", &joints.iter().map(|j| j.parent).collect::<Vec<_>>())?;
    let mut verts: Vec<Vec<Weight>> = Vec::new();
    let mut faces = Vec::new();
    for m in 0..num_meshes {
        let f = format!("mesh[{m}]");
        t.expect("mesh", &f)?;
        t.expect("{", &f)?;
        if t.toks.get(t.at) == Some(&"shader") {
            t.next(&f)?;
            t.next(&f)?;
        }
        let base = verts.len();
        let numverts: usize = t.keyed("numverts")?;
        let mut spans = Vec::new();
        for v in 0..numverts {
            let f = format!("mesh[{m}].vert[{v}]");
            t.expect("vert", &f)?;
            let _i: usize = t.num(&f)?;
            t.expect("(", &f)?;
            t.float(&f)?;
            t.float(&f)?;
            t.expect(")", &f)?;
            let start: usize = t.num(&f)?;
            let count: usize = t.num(&f)?;
            spans.push((start, count));
        }
        let numtris: usize = t.keyed("numtris")?;
        for k in 0..numtris {
            let f = format!("mesh[{m}].tri[{k}]");
            t.expect("tri", &f)?;
            let _i: usize = t.num(&f)?;
            let tri: [usize; 3] = [t.num(&f)?, t.num(&f)?, t.num(&f)?];
            if let Some(&i) = tri.iter().find(|&&i| i >= numverts) {
                return Err(t.err(&f, format!("vertex {i} of {numverts}")));
            }
            // MD5 winds clockwise; the clip convention is counter-clockwise.
            faces.push([tri[0], tri[2], tri[1]].map(|i| (base + i) as u32));
        }
        let numweights: usize = t.keyed("numweights")?;
        let mut weights = Vec::new();
        for w in 0..numweights {
            let f = format!("mesh[{m}].weight[{w}]");
            t.expect("weight", &f)?;
            let _i: usize = t.num(&f)?;
            let joint: usize = t.num(&f)?;
            let bias = t.float(&f)?;
            let pos = t.vec3(&f)?;
            if joint >= joints.len() {
                return Err(t.err(
                    &f,
                    format!("names joint {joint}, but the skeleton has {} joints", joints.len()),
                ));
            }
            weights.push(Weight { joint, bias, pos });
        }
        t.expect("}", &f)?;
        for (v, (start, count)) in spans.into_iter().enumerate() {
            if start.checked_add(count).is_none_or(|e| e > weights.len()) || count == 0 {
                return Err(t.err(
                    &format!("mesh[{m}].vert[{v}]"),
                    format!("weights {start}+{count} outside the mesh's {} weights", weights.len()),
                ));
            }
            verts.push(weights[start..start + count].to_vec());
        }
    }
    Ok(Mesh { joints, verts, faces })
}

struct Anim {
    /// Per frame, object-space `(position, rotation)` per joint.
    frames: Vec<Vec<([f64; 3], [f64; 4])>>,
}

/// What an `.md5anim` says about itself before its frames.
#[derive(Debug)]
struct AnimHeader {
    /// Joint names and parents.
    joints: Vec<(String, i32)>,
    frames: usize,
    fps: f32,
}

/// The header of an `.md5anim`, without reading the frames.
fn anim_header(path: &Path) -> Result<AnimHeader> {
    let text = read_text(path)?;
    let mut t = Tokens::new(path, &text);
    let (h, frames, fps, _) = anim_head(&mut t)?;
    Ok(AnimHeader {
        joints: h.into_iter().map(|(n, p, _, _)| (n, p)).collect(),
        frames,
        fps,
    })
}

type Hierarchy = Vec<(String, i32, u32, usize)>;

fn anim_head(t: &mut Tokens) -> Result<(Hierarchy, usize, f32, usize)> {
    header(t)?;
    let num_frames: usize = t.keyed("numFrames")?;
    let num_joints: usize = t.keyed("numJoints")?;
    let fps: f64 = t.keyed("frameRate")?;
    let fps = super::skeletal::check_fps(t.path, "frameRate", fps)?;
    let comps: usize = t.keyed("numAnimatedComponents")?;
    t.expect("hierarchy", "hierarchy")?;
    t.expect("{", "hierarchy")?;
    let mut h = Vec::new();
    for j in 0..num_joints {
        let f = format!("hierarchy[{j}]");
        let name = t.next(&f)?.to_owned();
        h.push((name, t.num(&f)?, t.num(&f)?, t.num(&f)?));
    }
    t.expect("}", "hierarchy")?;
    Ok((h, num_frames, fps, comps))
}

fn parse_anim(path: &Path, max_frames: usize) -> Result<Anim> {
    let text = read_text(path)?;
    let mut t = Tokens::new(path, &text);
    let (h, num_frames, _fps, comps) = anim_head(&mut t)?;
    skeletal::check_frames(path, &skeletal::stem(path), num_frames, max_frames)?;
    // Each frame needs `comps` numbers and each joint 6 base numbers: refuse counts the text cannot hold.
    let left = t.toks.len() - t.at;
    if num_frames.saturating_mul(comps).saturating_add(h.len() * 6) > left {
        return Err(t.err(
            "numFrames",
            format!("{num_frames} frames × {comps} components do not fit in the file's {left} remaining tokens"),
        ));
    }
    for (j, (_, _, flags, start)) in h.iter().enumerate() {
        let n = (flags & 63).count_ones() as usize;
        if start.checked_add(n).is_none_or(|e| e > comps) {
            return Err(t.err(
                &format!("hierarchy[{j}]"),
                "animated components past numAnimatedComponents",
            ));
        }
    }
    let parents = check_parents(path, "hierarchy", &h.iter().map(|x| x.1).collect::<Vec<_>>())?;
    t.expect("bounds", "bounds")?;
    t.expect("{", "bounds")?;
    for f in 0..num_frames {
        t.vec3(&format!("bounds[{f}]"))?;
        t.vec3(&format!("bounds[{f}]"))?;
    }
    t.expect("}", "bounds")?;
    t.expect("baseframe", "baseframe")?;
    t.expect("{", "baseframe")?;
    let mut base = Vec::new();
    for j in 0..h.len() {
        let f = format!("baseframe[{j}]");
        base.push((t.vec3(&f)?, t.vec3(&f)?));
    }
    t.expect("}", "baseframe")?;
    let mut frames = Vec::new();
    for f in 0..num_frames {
        let field = format!("frame[{f}]");
        t.expect("frame", &field)?;
        let _i: usize = t.num(&field)?;
        t.expect("{", &field)?;
        let vals = (0..comps).map(|_| t.float(&field)).collect::<Result<Vec<f64>>>()?;
        t.expect("}", &field)?;
        let mut out: Vec<([f64; 3], [f64; 4])> = Vec::with_capacity(h.len());
        for (j, (_, _, flags, start)) in h.iter().enumerate() {
            let (mut p, mut q) = base[j];
            let mut k = *start;
            for (bit, slot) in [(1, 0), (2, 1), (4, 2)] {
                if flags & bit != 0 {
                    p[slot] = vals[k];
                    k += 1;
                }
            }
            for (bit, slot) in [(8, 0), (16, 1), (32, 2)] {
                if flags & bit != 0 {
                    q[slot] = vals[k];
                    k += 1;
                }
            }
            let q = quat(q);
            let joint = match parents[j] {
                Some(pj) => {
                    let (pp, pq) = out[pj];
                    let r = quat_rotate(pq, p);
                    (
                        [r[0] + pp[0], r[1] + pp[1], r[2] + pp[2]],
                        skeletal::normalize_quat(quat_mul(pq, q)),
                    )
                }
                None => (p, q),
            };
            out.push(joint);
        }
        frames.push(out);
    }
    if !t.done() {
        return Err(t.err("frames", format!("unexpected `{}` after the last frame", t.toks[t.at])));
    }
    Ok(Anim { frames })
}

fn fits(mesh: &Mesh, hierarchy: &[(String, i32)]) -> bool {
    hierarchy.len() == mesh.joints.len()
        && hierarchy
            .iter()
            .zip(&mesh.joints)
            .all(|((n, p), j)| *n == j.name && *p == j.parent)
}

fn takes_of(path: &Path, mesh: &Mesh) -> Vec<TakeInfo> {
    skeletal::companions(path, &["md5anim"], false)
        .into_iter()
        .filter_map(|p| {
            let h = anim_header(&p).ok()?;
            fits(mesh, &h.joints).then(|| TakeInfo {
                name: skeletal::stem(&p),
                frames: h.frames,
                fps: h.fps,
                file: Some(p),
            })
        })
        .collect()
}

/// The takes of a `.md5mesh` (see the module doc).
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let mesh = parse_mesh(path)?;
    Ok(takes_of(path, &mesh))
}

/// Bake one take of a `.md5mesh` into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let mesh = parse_mesh(path)?;
    let takes = takes_of(path, &mesh);
    let info = takes[skeletal::pick(path, &takes, &opts.take)?].clone();
    let anim_path = info.file.clone().expect("md5 takes are files");
    let anim = parse_anim(&anim_path, opts.max_frames)?;
    let mut stats = SkinStats {
        vertices: mesh.verts.len(),
        ..SkinStats::default()
    };
    // Renormalise biases that do not sum to 1 (counted).
    let scale: Vec<f64> = mesh
        .verts
        .iter()
        .map(|ws| {
            if ws.len() > 4 {
                stats.over_four_weights += 1;
            }
            let s: f64 = ws.iter().map(|w| w.bias).sum();
            if (s - 1.0).abs() > skeletal::WEIGHT_SUM_TOLERANCE {
                stats.renormalised += 1;
            }
            if s > 0.0 { 1.0 / s } else { 0.0 }
        })
        .collect();
    if let Some(v) = scale.iter().position(|&s| s == 0.0) {
        return Err(DataError::new(
            path,
            "weights",
            format!("vertex {v} has no positive bias"),
        ));
    }
    let n = mesh.verts.len();
    skeletal::check_rows(path, anim.frames.len(), n)?;
    let mut vertices = Vec::with_capacity(anim.frames.len() * n);
    for frame in &anim.frames {
        for (ws, s) in mesh.verts.iter().zip(&scale) {
            let mut acc = [0.0; 3];
            for w in ws {
                let (jp, jq) = frame[w.joint];
                let r = quat_rotate(jq, w.pos);
                (0..3).for_each(|c| acc[c] += w.bias * s * (jp[c] + r[c]));
            }
            vertices.push(z_up_to_y_up(acc).map(|x| x as f32));
        }
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        anim.frames.len(),
        n,
        mesh.faces,
        "",
        path.display().to_string(),
    )?;
    Ok((clip, stats, info))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MESH: &str = r#"MD5Version 10
commandline ""
numJoints 2
numMeshes 1
joints {
	"root" -1 ( 0 0 0 ) ( 0 0 0 )		// comment
	"tip" 0 ( 0 0 1 ) ( 0 0 0 )
}
mesh {
	shader "skin"
	numverts 3
	vert 0 ( 0 0 ) 0 1
	vert 1 ( 0 0 ) 1 1
	vert 2 ( 0 0 ) 2 2
	numtris 1
	tri 0 0 1 2
	numweights 4
	weight 0 0 1 ( 1 0 0 )
	weight 1 0 1 ( 0 1 0 )
	weight 2 1 0.25 ( 0 0 0 )
	weight 3 1 0.25 ( 0 0 1 )
}
"#;

    fn anim(frames: usize) -> String {
        let mut s = format!(
            "MD5Version 10\ncommandline \"\"\nnumFrames {frames}\nnumJoints 2\nframeRate 24\nnumAnimatedComponents 1\n\
             hierarchy {{\n\"root\" -1 1 0\n\"tip\" 0 0 1\n}}\nbounds {{\n"
        );
        s += &"( 0 0 0 ) ( 1 1 1 )\n".repeat(frames);
        s += "}\nbaseframe {\n( 0 0 0 ) ( 0 0 0 )\n( 0 0 1 ) ( 0 0 0 )\n}\n";
        for f in 0..frames {
            s += &format!("frame {f} {{\n{}\n}}\n", f as f32 * 0.5);
        }
        s
    }

    #[test]
    fn bakes_weighted_joints_and_lists_matching_anims() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("thing.md5mesh");
        std::fs::write(&mesh, MESH).unwrap();
        std::fs::write(dir.path().join("slide.md5anim"), anim(3)).unwrap();
        std::fs::write(dir.path().join("other.md5anim"), anim(3).replace("\"tip\"", "\"toe\"")).unwrap();
        let takes = list_takes(&mesh).unwrap();
        assert_eq!(takes.len(), 1, "{takes:?}");
        assert_eq!((takes[0].name.as_str(), takes[0].frames), ("slide", 3));
        // Without its version and command lines the mesh reads the same; another version is refused.
        std::fs::write(&mesh, MESH.replacen("MD5Version 10\n", "", 1)).unwrap();
        assert_eq!(list_takes(&mesh).unwrap(), takes);
        std::fs::write(&mesh, MESH.replacen("MD5Version 10\ncommandline \"\"\n", "", 1)).unwrap();
        assert_eq!(list_takes(&mesh).unwrap(), takes);
        std::fs::write(&mesh, MESH.replacen("MD5Version 10", "MD5Version 11", 1)).unwrap();
        assert_eq!(list_takes(&mesh).unwrap_err().field, "MD5Version");
        std::fs::write(&mesh, MESH).unwrap();
        let (clip, stats, _) = read(&mesh, &ReadOptions::default()).unwrap();
        assert_eq!((clip.frames, clip.n_vertices), (3, 3));
        // Vertex 2's biases sum to 0.5: renormalised and counted; it sits at tip + (0,0,0.5) = (0,0,1.5).
        assert_eq!(stats.renormalised, 1);
        // Frame 2 moves the root by x = 1.0; Z-up (1, 0, 1.5) → Y-up (1, 1.5, 0).
        let v = clip.frame(2)[2];
        assert!(
            (v[0] - 1.0).abs() < 1e-6 && (v[1] - 1.5).abs() < 1e-6 && v[2].abs() < 1e-6,
            "{v:?}"
        );
    }

    #[test]
    fn an_animation_whose_frame_rate_is_not_finite_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.md5anim");
        for rate in ["nan", "inf", "-24"] {
            std::fs::write(&path, anim(3).replace("frameRate 24", &format!("frameRate {rate}"))).unwrap();
            let e = anim_header(&path).unwrap_err();
            assert!(e.field == "frameRate" && e.reason.contains("frame rate"), "{rate}: {e}");
        }
        std::fs::write(&path, anim(3)).unwrap();
        assert_eq!(anim_header(&path).unwrap().fps, 24.0);
    }

    #[test]
    fn refuses_missing_joints_long_anims_and_static_meshes() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("m.md5mesh");
        std::fs::write(&mesh, MESH.replace("weight 3 1 0.25", "weight 3 7 0.25")).unwrap();
        let e = list_takes(&mesh).unwrap_err();
        assert!(e.reason.contains("joint 7") && e.field.contains("weight[3]"), "{e}");

        std::fs::write(&mesh, MESH).unwrap();
        let e = read(&mesh, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("static mesh is not a clip"), "{e}");

        std::fs::write(dir.path().join("long.md5anim"), anim(50)).unwrap();
        let opts = ReadOptions {
            max_frames: 20,
            ..ReadOptions::default()
        };
        let e = read(&mesh, &opts).unwrap_err();
        assert!(e.reason.contains("50 frames, more than the maximum of 20"), "{e}");
        // A frame count the text cannot hold is refused before the frames are read.
        std::fs::write(
            dir.path().join("long.md5anim"),
            anim(2).replace("numFrames 2", "numFrames 4000"),
        )
        .unwrap();
        let e = read(&mesh, &ReadOptions::default()).unwrap_err();
        assert!(e.field == "numFrames" || e.field.starts_with("bounds"), "{e}");
    }
}
