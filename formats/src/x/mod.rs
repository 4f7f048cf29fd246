//! DirectX `.x` in its text form (`xof 0302txt` / `0303txt`, 32- or 64-bit floats): frame hierarchies holding
//! meshes, skin weights and animation sets, baked per key time.
//!
//! The file is a tree of data objects, `Type [name] { values… children… }`; templates are skipped and `{ name }`
//! is a reference. The takes are the `AnimationSet`s in file order, named by their own names (`take<i>` for an
//! unnamed one); a set whose keys all fall on one time is no motion and is not a take. Every mesh of the file is
//! read into one vertex list (polygons split into fans). A skinned mesh's vertex is `Σ_k w_k · G(j_k) · O_k · v`
//! with `O_k` its skin weights' offset matrix and `G` a frame's object-space transform; a vertex without weights,
//! and every vertex of an unskinned mesh, follows the frame that holds its mesh, `G(frame) · v`; so do the weights
//! of a `SkinWeights` naming a joint that is not a frame of the file (as assimp reads them: nothing moves it). A frame the take
//! animates is `T · R · S` from its position, rotation and scale keys (a kind it has no keys for comes from its
//! `FrameTransformMatrix`) or its matrix keys, linear between keys and held outside them; other frames keep their
//! matrix. The take is sampled at `t₀, t₀ + Δ, …, t₁`, Δ the greatest common divisor of the key times' offsets
//! from `t₀`, at `AnimTicksPerSecond / Δ` frames per second (4,800 ticks per second when the file does not say).
//!
//! DirectX multiplies row vectors (`v · M`) and stores rotation keys as `(w, x, y, z)` of that transposed
//! rotation: both are turned into this crate's column convention (matrix transposed, quaternion conjugated), and
//! the left-handed coordinates into right-handed ones (z mirrored, triangle windings reversed). Binary and
//! compressed `.x` files are refused with a reason. Nothing is allocated from a count the file states before the
//! values it counts have been read.

use std::collections::HashMap;
use std::path::Path;

use super::skeletal::{
    self, IDENTITY, Influences, Mat, ReadOptions, SkinStats, TakeInfo, clean_influences, globals, lerp3, mul,
    sample_keys, skin_frame, slerp, trs,
};
use crate::clip::Clip;
use crate::error::{DataError, Result};
use text::{Obj, Vals};

mod text;

/// Largest `.x` file read, in bytes.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

/// Deepest nesting of data objects read (frame hierarchies of real files are a few dozen deep).
pub const MAX_DEPTH: usize = 256;

/// Key-time unit rate when the file has no `AnimTicksPerSecond` (DirectX's default).
pub const DEFAULT_TICKS_PER_SECOND: f64 = 4800.0;

struct Frame<'a> {
    name: &'a str,
    parent: Option<usize>,
    rest: Mat,
}

struct Skin<'a> {
    bone: &'a str,
    vertices: Vec<usize>,
    weights: Vec<f64>,
    offset: Mat,
}

struct Mesh<'a> {
    frame: Option<usize>,
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    skins: Vec<Skin<'a>>,
}

#[derive(Default)]
struct Keys {
    rotation: Vec<(i64, [f64; 4])>,
    scale: Vec<(i64, [f64; 3])>,
    position: Vec<(i64, [f64; 3])>,
    matrix: Vec<(i64, Mat)>,
}

struct Set<'a> {
    name: String,
    /// Keys per animated frame name.
    tracks: Vec<(&'a str, Keys)>,
}

struct XFile<'a> {
    frames: Vec<Frame<'a>>,
    meshes: Vec<Mesh<'a>>,
    sets: Vec<Set<'a>>,
    ticks_per_second: f64,
}

fn parse<'a>(path: &Path, text: &'a str) -> Result<XFile<'a>> {
    let objs = text::objects(path, text)?;
    let mut file = XFile {
        frames: Vec::new(),
        meshes: Vec::new(),
        sets: Vec::new(),
        ticks_per_second: DEFAULT_TICKS_PER_SECOND,
    };
    let mut loose = Vec::new();
    for obj in &objs {
        match obj.kind {
            "Frame" => frame(path, obj, None, &mut file)?,
            "Mesh" => file.meshes.push(mesh(path, obj, None)?),
            "AnimTicksPerSecond" => {
                let t = Vals::new(path, obj).uint()?;
                if t == 0 {
                    return Err(DataError::new(path, "AnimTicksPerSecond", "0 ticks per second"));
                }
                file.ticks_per_second = t as f64;
            }
            "AnimationSet" => {
                let name = if obj.name.is_empty() {
                    format!("take{}", file.sets.len())
                } else {
                    obj.name.to_owned()
                };
                let mut tracks = Vec::new();
                for a in obj.children.iter().filter(|a| a.kind == "Animation") {
                    tracks.push(animation(path, a)?);
                }
                file.sets.push(Set { name, tracks });
            }
            "Animation" => loose.push(animation(path, obj)?),
            _ => {}
        }
    }
    if !loose.is_empty() {
        file.sets.push(Set {
            name: "all".into(),
            tracks: loose,
        });
    }
    if file.frames.len() > skeletal::MAX_JOINTS {
        return Err(DataError::new(
            path,
            "Frame",
            format!(
                "{} frames, more than the maximum of {}",
                file.frames.len(),
                skeletal::MAX_JOINTS
            ),
        ));
    }
    Ok(file)
}

fn frame<'a>(path: &Path, obj: &Obj<'a>, parent: Option<usize>, file: &mut XFile<'a>) -> Result<()> {
    let me = file.frames.len();
    let mut rest = IDENTITY;
    if let Some(m) = obj.children.iter().find(|c| c.kind == "FrameTransformMatrix") {
        rest = Vals::new(path, m).matrix()?;
    }
    file.frames.push(Frame {
        name: obj.name,
        parent,
        rest,
    });
    for child in &obj.children {
        match child.kind {
            "Frame" => frame(path, child, Some(me), file)?,
            "Mesh" => file.meshes.push(mesh(path, child, Some(me))?),
            _ => {}
        }
    }
    Ok(())
}

fn mesh<'a>(path: &Path, obj: &Obj<'a>, frame: Option<usize>) -> Result<Mesh<'a>> {
    let mut v = Vals::new(path, obj);
    let n = v.count(3)?;
    let mut positions = Vec::with_capacity(n);
    for _ in 0..n {
        positions.push(v.vec3()?);
    }
    let n_faces = v.count(1)?;
    let mut faces = Vec::new();
    for f in 0..n_faces {
        let k = v.count(1)?;
        if k < 3 {
            return Err(v.err(format!("face {f} has {k} corners; a face needs at least 3")));
        }
        let mut corners = Vec::with_capacity(k);
        for _ in 0..k {
            corners.push(v.vertex(n, || format!("face {f}"))? as u32);
        }
        faces.extend((1..k - 1).map(|c| [corners[0], corners[c], corners[c + 1]]));
    }
    let mut skins = Vec::new();
    for s in obj.children.iter().filter(|c| c.kind == "SkinWeights") {
        let mut v = Vals::new(path, s);
        let bone = v.string()?;
        let k = v.count(2)?;
        let mut vertices = Vec::with_capacity(k);
        for _ in 0..k {
            vertices.push(v.vertex(n, || "a skin weight".into())?);
        }
        let weights = (0..k).map(|_| v.float()).collect::<Result<Vec<f64>>>()?;
        let offset = v.matrix()?;
        skins.push(Skin {
            bone,
            vertices,
            weights,
            offset,
        });
    }
    Ok(Mesh {
        frame,
        positions,
        faces,
        skins,
    })
}

fn animation<'a>(path: &Path, obj: &Obj<'a>) -> Result<(&'a str, Keys)> {
    let target = obj
        .refs
        .first()
        .copied()
        .or_else(|| obj.children.iter().find(|c| c.kind == "Frame").map(|c| c.name))
        .ok_or_else(|| DataError::new(path, format!("Animation {}", obj.name), "names no frame (`{ name }`)"))?;
    let mut keys = Keys::default();
    for k in obj.children.iter().filter(|c| c.kind == "AnimationKey") {
        let mut v = Vals::new(path, k);
        let kind = v.uint()?;
        let width = match kind {
            0 => 4,
            1 | 2 => 3,
            3 | 4 => 16,
            other => {
                return Err(v.err(format!(
                    "key type {other} (expected 0 rotation, 1 scale, 2 position, 4 matrix)"
                )));
            }
        };
        let n = v.count(2 + width)?;
        for _ in 0..n {
            let t = v.uint()?;
            if t > u64::from(u32::MAX) {
                return Err(v.err(format!("key time {t} does not fit the file's 32-bit tick count")));
            }
            let t = t as i64;
            let w = v.uint()?;
            if w != width as u64 {
                return Err(v.err(format!("a key of type {kind} with {w} values (expected {width})")));
            }
            match kind {
                // (w, x, y, z) of the row-vector rotation: its conjugate, as (x, y, z, w), turns column vectors.
                0 => {
                    let [w, x, y, z] = [v.float()?, v.float()?, v.float()?, v.float()?];
                    keys.rotation.push((t, skeletal::normalize_quat([-x, -y, -z, w])));
                }
                1 => keys.scale.push((t, v.vec3()?)),
                2 => keys.position.push((t, v.vec3()?)),
                _ => keys.matrix.push((t, v.matrix()?)),
            }
        }
    }
    keys.rotation.sort_by_key(|k| k.0);
    keys.scale.sort_by_key(|k| k.0);
    keys.position.sort_by_key(|k| k.0);
    keys.matrix.sort_by_key(|k| k.0);
    Ok((target, keys))
}

impl Keys {
    fn times(&self) -> Vec<i64> {
        let mut t: Vec<i64> = self.rotation.iter().map(|k| k.0).collect();
        t.extend(self.scale.iter().map(|k| k.0));
        t.extend(self.position.iter().map(|k| k.0));
        t.extend(self.matrix.iter().map(|k| k.0));
        t
    }

    /// The frame's local transform at tick `t`, `rest` supplying what the keys leave out.
    fn local(&self, t: i64, rest: &Mat) -> Mat {
        if let Some(m) = sample_keys(&self.matrix, t, |a, b, f| {
            std::array::from_fn(|r| std::array::from_fn(|c| a[r][c] + f * (b[r][c] - a[r][c])))
        }) {
            return m;
        }
        let (rest_t, rest_q, rest_s) = decompose(rest);
        trs(
            sample_keys(&self.position, t, lerp3).unwrap_or(rest_t),
            sample_keys(&self.rotation, t, slerp).unwrap_or(rest_q),
            sample_keys(&self.scale, t, lerp3).unwrap_or(rest_s),
        )
    }
}

/// Translation, unit quaternion `(x, y, z, w)` and scale of an affine matrix without shear.
fn decompose(m: &Mat) -> ([f64; 3], [f64; 4], [f64; 3]) {
    let t = [m[0][3], m[1][3], m[2][3]];
    let s: [f64; 3] = std::array::from_fn(|c| (0..3).map(|r| m[r][c] * m[r][c]).sum::<f64>().sqrt());
    let r = |i: usize, j: usize| if s[j] > 0.0 { m[i][j] / s[j] } else { 0.0 };
    let trace = r(0, 0) + r(1, 1) + r(2, 2);
    let q = if trace > 0.0 {
        let k = 0.5 / (trace + 1.0).sqrt();
        [
            (r(2, 1) - r(1, 2)) * k,
            (r(0, 2) - r(2, 0)) * k,
            (r(1, 0) - r(0, 1)) * k,
            0.25 / k,
        ]
    } else if r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2) {
        let k = 2.0 * (1.0 + r(0, 0) - r(1, 1) - r(2, 2)).max(0.0).sqrt();
        [
            0.25 * k,
            (r(0, 1) + r(1, 0)) / k,
            (r(0, 2) + r(2, 0)) / k,
            (r(2, 1) - r(1, 2)) / k,
        ]
    } else if r(1, 1) > r(2, 2) {
        let k = 2.0 * (1.0 + r(1, 1) - r(0, 0) - r(2, 2)).max(0.0).sqrt();
        [
            (r(0, 1) + r(1, 0)) / k,
            0.25 * k,
            (r(1, 2) + r(2, 1)) / k,
            (r(0, 2) - r(2, 0)) / k,
        ]
    } else {
        let k = 2.0 * (1.0 + r(2, 2) - r(0, 0) - r(1, 1)).max(0.0).sqrt();
        [
            (r(0, 2) + r(2, 0)) / k,
            (r(1, 2) + r(2, 1)) / k,
            0.25 * k,
            (r(1, 0) - r(0, 1)) / k,
        ]
    };
    (t, skeletal::normalize_quat(q), s)
}

/// First key tick, frame step and frame count of a take (`None` without keys).
fn timeline(set: &Set) -> Option<(i64, i64, i64)> {
    let times: Vec<i64> = set.tracks.iter().flat_map(|(_, k)| k.times()).collect();
    let first = *times.iter().min()?;
    let last = *times.iter().max()?;
    let step = times.iter().fold(0, |g, &t| gcd(g, t - first));
    Some(if step == 0 {
        (first, 1, 1)
    } else {
        (first, step, (last - first) / step + 1)
    })
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

fn takes(file: &XFile) -> Vec<(usize, TakeInfo)> {
    let mut out = Vec::new();
    for (i, set) in file.sets.iter().enumerate() {
        let Some((_, step, frames)) = timeline(set) else {
            continue;
        };
        if frames < 2 {
            continue;
        }
        out.push((
            i,
            TakeInfo {
                name: set.name.clone(),
                frames: usize::try_from(frames).unwrap_or(usize::MAX),
                fps: super::skeletal::fps_or_unknown(file.ticks_per_second / step as f64),
                file: None,
            },
        ));
    }
    out
}

/// The file as text: bytes that are not UTF-8 (Latin-1 names and comments in real files) become U+FFFD, which
/// only ever lands in names and comments; a binary or compressed file is refused by its header first.
fn read_text(path: &Path) -> Result<String> {
    let bytes = super::read_file(path, MAX_TEXT_BYTES.min(crate::limits::FILE_BYTES.get()))?;
    text::header(path, &String::from_utf8_lossy(&bytes[..bytes.len().min(16)]))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// The takes of a `.x` file: its animation sets with at least two key times.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let text = read_text(path)?;
    Ok(takes(&parse(path, &text)?).into_iter().map(|(_, t)| t).collect())
}

/// The animation sets of a `.x` file whose keys all fall on one time (poses, not takes), by name.
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    let text = read_text(path)?;
    let file = parse(path, &text)?;
    Ok(file
        .sets
        .iter()
        .filter(|set| timeline(set).is_some_and(|(_, _, frames)| frames < 2))
        .map(|set| set.name.clone())
        .collect())
}

/// Bake take `opts.take` of a `.x` file into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let text = read_text(path)?;
    let file = parse(path, &text)?;
    if file.meshes.iter().all(|m| m.positions.is_empty()) {
        return Err(DataError::new(path, "Mesh", "no mesh in the file"));
    }
    let all = takes(&file);
    let list: Vec<TakeInfo> = all.iter().map(|(_, t)| t.clone()).collect();
    let pick = skeletal::pick(path, &list, &opts.take)?;
    let (set_index, info) = all[pick].clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    let set = &file.sets[set_index];
    let (first, step, _) = timeline(set).expect("a take has keys");

    let by_name: HashMap<&str, usize> = file.frames.iter().enumerate().map(|(i, f)| (f.name, i)).collect();
    let mut tracks: Vec<Option<&Keys>> = vec![None; file.frames.len()];
    for (name, keys) in &set.tracks {
        let j = by_name.get(name).ok_or_else(|| {
            DataError::new(
                path,
                format!("AnimationSet {}", set.name),
                format!("animates frame {name:?}, which the file does not have"),
            )
        })?;
        tracks[*j] = Some(keys);
    }
    let parents: Vec<Option<usize>> = file.frames.iter().map(|f| f.parent).collect();

    // One skin matrix per (mesh, weight list) plus one per frame for rigid vertices: indices into `skin` below.
    let n_frames = file.frames.len();
    let mut bind = Vec::new();
    let mut infl: Influences = Vec::new();
    let mut faces = Vec::new();
    let mut bones: Vec<(usize, Mat)> = Vec::new();
    for mesh in &file.meshes {
        let base = bind.len() as u32;
        // Rigid vertices follow the mesh's frame, or the identity (slot `n_frames`) for a mesh outside every frame.
        let rigid = mesh.frame.unwrap_or(n_frames);
        let mut lists: Influences = vec![Vec::new(); mesh.positions.len()];
        for s in &mesh.skins {
            // Weights on a joint that is not a frame of the file (assimp reads such files) hold their vertices
            // to the mesh as if unskinned: nothing animates that joint.
            let slot = match by_name.get(s.bone) {
                Some(&j) => {
                    bones.push((j, s.offset));
                    n_frames + bones.len()
                }
                None => rigid,
            };
            for (&v, &w) in s.vertices.iter().zip(&s.weights) {
                lists[v].push((slot, w));
            }
        }
        for list in &mut lists {
            if list.iter().all(|&(_, w)| w == 0.0) {
                *list = vec![(rigid, 1.0)];
            }
        }
        bind.extend_from_slice(&mesh.positions);
        infl.extend(lists);
        faces.extend(mesh.faces.iter().map(|f| f.map(|i| i + base)));
    }
    let stats = clean_influences(path, "SkinWeights", &mut infl, n_frames + 1 + bones.len())?;

    skeletal::check_rows(path, info.frames, bind.len())?;
    let mut vertices = Vec::with_capacity(info.frames * bind.len());
    for f in 0..info.frames as i64 {
        let t = first + f * step;
        let locals: Vec<Mat> = file
            .frames
            .iter()
            .zip(&tracks)
            .map(|(fr, keys)| keys.map_or(fr.rest, |k| k.local(t, &fr.rest)))
            .collect();
        let g = globals(&parents, &locals);
        let mut skin = g.clone();
        skin.push(IDENTITY);
        skin.extend(bones.iter().map(|(j, offset)| mul(&g[*j], offset)));
        skin_frame(&bind, &infl, &skin, &mut vertices);
    }
    let faces = skeletal::to_right_handed(&mut vertices, faces);
    let clip = skeletal::baked_clip(path, vertices, info.frames, faces)?;
    Ok((clip, stats, info))
}

/// Text of a `.x` for tests and `bench data`: one mesh outside every frame (`positions`, triangles `faces`),
/// vertex `v` fully skinned to root frame `j<skin[v]>` (rest and offset matrices the identity), and one
/// animation set `walk` that puts frame `j` at `keys[f][j]` at tick 160 f (30 frames per second at 4,800 ticks
/// per second).
#[doc(hidden)]
pub fn write_test_x(positions: &[[f32; 3]], faces: &[[u32; 3]], skin: &[u8], keys: &[Vec<[f32; 3]>]) -> String {
    use std::fmt::Write as _;
    const ID: &str = "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1;;";
    let joints = keys.first().map_or(0, Vec::len);
    let mut s = String::from("xof 0303txt 0032\nAnimTicksPerSecond { 4800; }\n");
    for j in 0..joints {
        let _ = writeln!(s, "Frame j{j} {{ FrameTransformMatrix {{ {ID} }} }}");
    }
    let _ = writeln!(s, "Mesh m {{\n{};", positions.len());
    for p in positions {
        let _ = write!(s, "{};{};{};,", p[0], p[1], p[2]);
    }
    let _ = writeln!(s, ";\n{};", faces.len());
    for f in faces {
        let _ = write!(s, "3;{},{},{};,", f[0], f[1], f[2]);
    }
    s += ";\n";
    for j in 0..joints {
        let verts: Vec<usize> = (0..positions.len()).filter(|&v| usize::from(skin[v]) == j).collect();
        let _ = write!(s, "SkinWeights {{ \"j{j}\"; {};", verts.len());
        verts.iter().for_each(|v| _ = write!(s, "{v},"));
        s += ";";
        verts.iter().for_each(|_| s += "1.0,");
        let _ = writeln!(s, "; {ID} }}");
    }
    s += "}\nAnimationSet walk {\n";
    for j in 0..joints {
        let _ = write!(s, "Animation {{ {{ j{j} }} AnimationKey {{ 2; {};", keys.len());
        for (f, frame) in keys.iter().enumerate() {
            let p = frame[j];
            let _ = write!(s, "{};3;{},{},{};;,", 160 * f, p[0], p[1], p[2]);
        }
        s += "; } }\n";
    }
    s += "}\n";
    s
}

#[cfg(test)]
mod tests;
