//! Inter-Quake Model `.iqm` (version 2): a skinned mesh baked per animation frame with linear blend skinning.
//!
//! A file holds meshes, joints, poses and animations, or only some of them: Red Eclipse ships one mesh file per
//! character and one animation-only file per move. The takes of a file with a mesh are its own animations, or,
//! when it has none, the animations of the animation-only `.iqm` files beside it and in its parent folder whose
//! pose count equals the mesh's joint count and whose joint names (when they have any) equal the mesh's; then
//! the `.bvh` files in its folder, retargeted onto its skeleton by joint name ([`super::bvh`]). Every
//! mesh of the file is read (faces offset into one vertex list); frames are the file's own frames (no
//! resampling); coordinates go from IQM's Z-up to Y-up ([`super::skeletal::z_up_to_y_up`]).
//!
//! Layout (all little-endian): a 124-byte header (`INTERQUAKEMODEL\0`, version, file size, flags, then
//! count/offset pairs), meshes of 6 u32, vertex arrays of 5 u32, triangles of 3 u32, joints of
//! `name u32, parent i32, t f32×3, q f32×4, s f32×3`, poses of `parent i32, mask u32, offset f32×10,
//! scale f32×10`, animations of `name, first, count u32, framerate f32, flags u32`, and u16 frame channels.

use std::path::{Path, PathBuf};

use super::bvh;
use super::bytes::Bytes;
use super::skeletal::{
    self, Influences, Mat, ReadOptions, SkinStats, TakeInfo, check_parents, clean_influences, globals, inverse, mul,
    skin_frame, trs, z_up_to_y_up,
};
use crate::clip::Clip;
use crate::error::{DataError, Result};

const MAGIC: &[u8; 16] = b"INTERQUAKEMODEL\0";
const HEADER: usize = 124;

struct Joint {
    name: String,
    parent: i32,
    local: Mat,
}

struct Pose {
    parent: i32,
    mask: u32,
    offset: [f32; 10],
    scale: [f32; 10],
}

struct Anim {
    name: String,
    first: usize,
    count: usize,
    fps: f32,
}

struct Mesh {
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    influences: Option<Influences>,
}

/// A parsed `.iqm`.
struct Iqm {
    joints: Vec<Joint>,
    poses: Vec<Pose>,
    anims: Vec<Anim>,
    channels: usize,
    frames: Vec<u16>,
    mesh: Option<Mesh>,
}

/// Whether `path` is an `.iqm` holding at least one mesh (animation-only files are companions, not clips).
pub fn has_mesh(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; HEADER];
    // A FIFO or device named `.iqm` is not opened (opening one could block).
    let ok = std::fs::metadata(path).is_ok_and(|m| m.is_file())
        && std::fs::File::open(path)
            .and_then(|mut f| f.read_exact(&mut head))
            .is_ok();
    ok && &head[..16] == MAGIC && u32::from_le_bytes(head[36..40].try_into().expect("4 bytes")) > 0
}

fn parse(path: &Path, data: &[u8]) -> Result<Iqm> {
    let p = path.display().to_string();
    let mut b = Bytes::new(&p, data);
    if b.take(16, "magic").ok() != Some(&MAGIC[..]) {
        return Err(b.err("magic", "not an IQM file (no INTERQUAKEMODEL header)"));
    }
    let version = b.u32("version")?;
    if version != 2 {
        return Err(b.err("version", format!("version {version}, only 2 is supported")));
    }
    let mut h = [0usize; 26];
    for (i, x) in h.iter_mut().enumerate() {
        *x = b.usize(&format!("header[{i}]"))?;
    }
    let [
        _filesize,
        _flags,
        _num_text,
        ofs_text,
        num_meshes,
        ofs_meshes,
        num_va,
        num_vertexes,
        ofs_va,
        num_tris,
        ofs_tris,
        _ofs_adj,
        num_joints,
        ofs_joints,
        num_poses,
        ofs_poses,
        num_anims,
        ofs_anims,
        num_frames,
        num_channels,
        ofs_frames,
        ..,
    ] = h;
    let text = |ofs: usize| -> String {
        let start = ofs_text.saturating_add(ofs);
        if start >= data.len() {
            return String::new();
        }
        let s = &data[start..];
        let end = s.iter().position(|&c| c == 0).unwrap_or(s.len());
        String::from_utf8_lossy(&s[..end]).into_owned()
    };

    if num_joints > skeletal::MAX_JOINTS || num_poses > skeletal::MAX_JOINTS {
        return Err(b.err(
            "num_joints",
            format!(
                "{num_joints} joints / {num_poses} poses, more than the limit {}",
                skeletal::MAX_JOINTS
            ),
        ));
    }
    b.check_count_at(ofs_joints, num_joints, 48, "joints")?;
    b.seek(ofs_joints, "ofs_joints")?;
    let mut joints = Vec::with_capacity(num_joints);
    for j in 0..num_joints {
        let f = format!("joints[{j}]");
        let name = b.u32(&f)? as usize;
        let parent = b.i32(&f)?;
        let t = b.f32s::<3>(&f)?.map(f64::from);
        let q = b.f32s::<4>(&f)?.map(f64::from);
        let s = b.f32s::<3>(&f)?.map(f64::from);
        joints.push(Joint {
            name: text(name),
            parent,
            local: trs(t, q, s),
        });
    }
    b.check_count_at(ofs_poses, num_poses, 88, "poses")?;
    b.seek(ofs_poses, "ofs_poses")?;
    let mut poses = Vec::with_capacity(num_poses);
    for j in 0..num_poses {
        let f = format!("poses[{j}]");
        poses.push(Pose {
            parent: b.i32(&f)?,
            mask: b.u32(&f)?,
            offset: b.f32s(&f)?,
            scale: b.f32s(&f)?,
        });
    }
    let used: usize = poses.iter().map(|p| (p.mask & 0x3ff).count_ones() as usize).sum();
    if num_poses > 0 && num_frames > 0 && used != num_channels {
        return Err(b.err(
            "num_framechannels",
            format!("{num_channels} channels per frame, but the pose masks use {used}"),
        ));
    }
    b.check_count_at(ofs_anims, num_anims, 20, "anims")?;
    b.seek(ofs_anims, "ofs_anims")?;
    let mut anims = Vec::with_capacity(num_anims);
    for a in 0..num_anims {
        let f = format!("anims[{a}]");
        let name = b.u32(&f)? as usize;
        let first = b.usize(&f)?;
        let count = b.usize(&f)?;
        let fps = b.f32(&f)?;
        if !super::skeletal::fps_in_range(f64::from(fps)) {
            return Err(b.err(
                &f,
                format!(
                    "frame rate {fps}: must be finite, not negative and at most {}",
                    super::skeletal::MAX_FPS
                ),
            ));
        }
        let _flags = b.u32(&f)?;
        if first.checked_add(count).is_none_or(|end| end > num_frames) {
            return Err(b.err(
                &f,
                format!("frames {first}..{first}+{count} lie past the file's {num_frames} frames"),
            ));
        }
        anims.push(Anim {
            name: text(name),
            first,
            count,
            fps,
        });
    }
    let total = num_frames
        .checked_mul(num_channels)
        .ok_or_else(|| b.err("num_frames", "frames × channels overflows"))?;
    b.check_count_at(ofs_frames, total, 2, "frames")?;
    b.seek(ofs_frames, "ofs_frames")?;
    let frames = (0..total).map(|_| b.u16("frames")).collect::<Result<Vec<u16>>>()?;

    let mesh = if num_meshes == 0 {
        None
    } else {
        Some(read_mesh(
            &mut b,
            num_meshes,
            ofs_meshes,
            num_va,
            num_vertexes,
            ofs_va,
            num_tris,
            ofs_tris,
        )?)
    };
    Ok(Iqm {
        joints,
        poses,
        anims,
        channels: num_channels,
        frames,
        mesh,
    })
}

#[allow(clippy::too_many_arguments)]
fn read_mesh(
    b: &mut Bytes,
    num_meshes: usize,
    ofs_meshes: usize,
    num_va: usize,
    num_vertexes: usize,
    ofs_va: usize,
    num_tris: usize,
    ofs_tris: usize,
) -> Result<Mesh> {
    b.check_count_at(ofs_meshes, num_meshes, 24, "meshes")?;
    b.check_count_at(ofs_va, num_va, 20, "vertexarrays")?;
    b.check_count_at(ofs_tris, num_tris, 12, "triangles")?;
    // Every vertex needs at least 12 bytes of positions somewhere in the file.
    b.check_count_at(0, num_vertexes, 12, "num_vertexes")?;
    b.seek(ofs_meshes, "ofs_meshes")?;
    let mut ranges = Vec::with_capacity(num_meshes);
    for m in 0..num_meshes {
        let f = format!("meshes[{m}]");
        let _name = b.u32(&f)?;
        let _material = b.u32(&f)?;
        let (fv, nv, ft, nt) = (b.usize(&f)?, b.usize(&f)?, b.usize(&f)?, b.usize(&f)?);
        if fv.checked_add(nv).is_none_or(|e| e > num_vertexes) || ft.checked_add(nt).is_none_or(|e| e > num_tris) {
            return Err(b.err(&f, "vertex or triangle range lies past the file's counts"));
        }
        ranges.push((fv, nv, ft, nt));
    }
    b.seek(ofs_va, "ofs_vertexarrays")?;
    let mut arrays = Vec::with_capacity(num_va);
    for a in 0..num_va {
        let f = format!("vertexarrays[{a}]");
        arrays.push((b.u32(&f)?, b.u32(&f)?, b.u32(&f)?, b.usize(&f)?, b.usize(&f)?));
    }
    let find = |kind: u32| arrays.iter().find(|a| a.0 == kind).copied();
    let (_, _, format, size, ofs) = find(0).ok_or_else(|| b.err("vertexarrays", "no POSITION array"))?;
    if format != 7 || size != 3 {
        return Err(b.err(
            "vertexarrays",
            format!("POSITION is format {format} × {size}, expected float × 3"),
        ));
    }
    b.check_count_at(ofs, num_vertexes, 12, "POSITION")?;
    b.seek(ofs, "POSITION")?;
    let mut positions = Vec::with_capacity(num_vertexes);
    for _ in 0..num_vertexes {
        positions.push(b.f32s::<3>("POSITION")?.map(f64::from));
    }
    let influences = match (find(4), find(5)) {
        (Some((_, _, fi, si, oi)), Some((_, _, fw, sw, ow))) => {
            if fi != 1 || si != 4 || sw != 4 || !(fw == 1 || fw == 7) {
                return Err(b.err(
                    "vertexarrays",
                    format!("blend arrays are format {fi}×{si} / {fw}×{sw}, expected ubyte×4 / (ubyte|float)×4"),
                ));
            }
            b.check_count_at(oi, num_vertexes, 4, "BLENDINDEXES")?;
            b.check_count_at(ow, num_vertexes, if fw == 7 { 16 } else { 4 }, "BLENDWEIGHTS")?;
            let mut infl: Influences = Vec::with_capacity(num_vertexes);
            for v in 0..num_vertexes {
                b.seek(oi + 4 * v, "BLENDINDEXES")?;
                let idx = b.take(4, "BLENDINDEXES")?.to_vec();
                let w: [f64; 4] = if fw == 7 {
                    b.seek(ow + 16 * v, "BLENDWEIGHTS")?;
                    b.f32s::<4>("BLENDWEIGHTS")?.map(f64::from)
                } else {
                    b.seek(ow + 4 * v, "BLENDWEIGHTS")?;
                    let raw = b.take(4, "BLENDWEIGHTS")?;
                    std::array::from_fn(|k| raw[k] as f64 / 255.0)
                };
                infl.push(idx.iter().zip(w).map(|(&j, w)| (j as usize, w)).collect());
            }
            Some(infl)
        }
        _ => None,
    };
    let mut faces = Vec::with_capacity(num_tris);
    for (m, &(fv, nv, ft, nt)) in ranges.iter().enumerate() {
        b.seek(ofs_tris + 12 * ft, "ofs_triangles")?;
        for t in 0..nt {
            let tri = [b.u32("triangles")?, b.u32("triangles")?, b.u32("triangles")?];
            if let Some(&i) = tri.iter().find(|&&i| (i as usize) < fv || (i as usize) >= fv + nv) {
                return Err(b.err(
                    format!("meshes[{m}].triangles[{t}]"),
                    format!("vertex {i} lies outside the mesh's vertices {fv}..{}", fv + nv),
                ));
            }
            // IQM winds clockwise; the clip convention is counter-clockwise.
            faces.push([tri[0], tri[2], tri[1]]);
        }
    }
    Ok(Mesh {
        positions,
        faces,
        influences,
    })
}

fn load(path: &Path) -> Result<Iqm> {
    let data = super::read_clip_file(path)?;
    parse(path, &data)
}

/// Where a take's frames come from: an animation of this or another `.iqm`, or a BVH retargeted onto the mesh.
enum Source {
    Iqm { file: Option<PathBuf>, anim: usize },
    Bvh(PathBuf),
}

/// Whether the animation file `anim` fits the skeleton of `mesh`.
fn compatible(mesh: &Iqm, anim: &Iqm) -> bool {
    anim.poses.len() == mesh.joints.len()
        && anim.poses.iter().zip(&mesh.joints).all(|(p, j)| p.parent == j.parent)
        && (anim.joints.is_empty()
            || (anim.joints.len() == mesh.joints.len()
                && anim.joints.iter().zip(&mesh.joints).all(|(a, m)| a.name == m.name)))
}

fn take_list(path: &Path, iqm: &Iqm) -> Vec<(TakeInfo, Source)> {
    let own = |f: &Iqm, file: Option<PathBuf>| -> Vec<(TakeInfo, Source)> {
        f.anims
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let name = match (&file, a.name.is_empty()) {
                    (_, false) => a.name.clone(),
                    (Some(p), true) => skeletal::stem(p),
                    (None, true) => format!("anim{i}"),
                };
                (
                    TakeInfo {
                        name,
                        frames: a.count,
                        fps: a.fps,
                        file: file.clone(),
                    },
                    Source::Iqm {
                        file: file.clone(),
                        anim: i,
                    },
                )
            })
            .collect()
    };
    if iqm.mesh.is_none() {
        return own(iqm, None);
    }
    let mut out = own(iqm, None);
    let companions = if iqm.anims.is_empty() {
        skeletal::companions(path, &["iqm"], true)
    } else {
        Vec::new()
    };
    for p in companions {
        if let Ok(other) = load(&p)
            && other.mesh.is_none()
            && compatible(iqm, &other)
        {
            let mut takes = own(&other, Some(p.clone()));
            // An animation file named after its move ("walk_forward.iqm") names the take better than a
            // generic animation name inside it.
            if takes.len() == 1 {
                takes[0].0.name = skeletal::stem(&p);
            }
            out.extend(takes);
        }
    }
    // Motion capture beside the mesh, retargeted by joint name (listed even when nothing maps: reading it then
    // says which joints failed to match).
    for p in skeletal::companions(path, &["bvh"], false) {
        if let Ok(b) = bvh::parse(&p, usize::MAX, false) {
            let info = TakeInfo {
                name: skeletal::stem(&p),
                frames: b.frames,
                fps: b.fps,
                file: Some(p.clone()),
            };
            out.push((info, Source::Bvh(p)));
        }
    }
    out
}

/// The takes of an `.iqm` file (see the module doc).
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let iqm = load(path)?;
    Ok(take_list(path, &iqm).into_iter().map(|(t, _)| t).collect())
}

/// Bake one take of an `.iqm` into a clip (id = file stem, caption empty: the importer captions).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let iqm = load(path)?;
    let err = |field: &str, reason: String| DataError::new(path, field, reason);
    let mesh = iqm
        .mesh
        .as_ref()
        .ok_or_else(|| err("meshes", "an animation-only file: read the mesh file beside it".into()))?;
    let takes = take_list(path, &iqm);
    let infos: Vec<TakeInfo> = takes.iter().map(|(t, _)| t.clone()).collect();
    let k = skeletal::pick(path, &infos, &opts.take)?;
    let (info, src) = &takes[k];
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    let (file, anim) = match src {
        Source::Iqm { file, anim } => (file, *anim),
        Source::Bvh(p) => return read_bvh(path, &iqm, mesh, p, info, opts),
    };
    let other;
    let anim_file: &Iqm = match file {
        None => &iqm,
        Some(p) => {
            other = load(p)?;
            &other
        }
    };
    let anim_path = file.as_deref().unwrap_or(path);
    let anim = &anim_file.anims[anim];
    let n = mesh.positions.len();
    let mut infl = mesh.influences.clone().ok_or_else(|| {
        err(
            "vertexarrays",
            "the mesh has no BLENDINDEXES/BLENDWEIGHTS: nothing to animate".into(),
        )
    })?;
    let joints = iqm.joints.len();
    let stats = clean_influences(path, "BLENDINDEXES", &mut infl, joints)?;
    if anim_file.poses.len() != joints {
        return Err(DataError::new(
            anim_path,
            "poses",
            format!("{} poses for a skeleton of {joints} joints", anim_file.poses.len()),
        ));
    }
    let parents = check_parents(path, "joints", &iqm.joints.iter().map(|j| j.parent).collect::<Vec<_>>())?;
    let bind = globals(&parents, &iqm.joints.iter().map(|j| j.local).collect::<Vec<_>>());
    let inv_bind: Vec<Mat> = bind
        .iter()
        .enumerate()
        .map(|(j, m)| inverse(m).ok_or_else(|| err(&format!("joints[{j}]"), "singular bind transform".into())))
        .collect::<Result<_>>()?;
    skeletal::check_rows(path, info.frames, n)?;
    let mut vertices = Vec::with_capacity(info.frames * n);
    for f in 0..anim.count {
        let row = &anim_file.frames[(anim.first + f) * anim_file.channels..];
        let mut c = 0;
        let locals: Vec<Mat> = anim_file
            .poses
            .iter()
            .map(|pose| {
                let v: [f64; 10] = std::array::from_fn(|k| {
                    let mut x = pose.offset[k] as f64;
                    if pose.mask & (1 << k) != 0 {
                        x += row[c] as f64 * pose.scale[k] as f64;
                        c += 1;
                    }
                    x
                });
                trs([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]], [v[7], v[8], v[9]])
            })
            .collect();
        let g = globals(&parents, &locals);
        let skin: Vec<Mat> = g.iter().zip(&inv_bind).map(|(a, b)| mul(a, b)).collect();
        let start = vertices.len();
        skin_frame(&mesh.positions, &infl, &skin, &mut vertices);
        for p in &mut vertices[start..] {
            *p = z_up_to_y_up(p.map(f64::from)).map(|x| x as f32);
        }
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        anim.count,
        n,
        mesh.faces.clone(),
        "",
        path.display().to_string(),
    )?;
    Ok((clip, stats, info.clone()))
}

/// Bake the BVH take `bvh_path` onto the mesh of `iqm` ([`bvh::retarget`]).
fn read_bvh(
    path: &Path,
    iqm: &Iqm,
    mesh: &Mesh,
    bvh_path: &Path,
    info: &TakeInfo,
    opts: &ReadOptions,
) -> Result<(Clip, SkinStats, TakeInfo)> {
    let motion = bvh::parse(bvh_path, opts.max_frames, true)?;
    let mut infl = mesh.influences.clone().ok_or_else(|| {
        DataError::new(
            path,
            "vertexarrays",
            "the mesh has no BLENDINDEXES/BLENDWEIGHTS: nothing to animate",
        )
    })?;
    let stats = clean_influences(path, "BLENDINDEXES", &mut infl, iqm.joints.len())?;
    let parents = check_parents(path, "joints", &iqm.joints.iter().map(|j| j.parent).collect::<Vec<_>>())?;
    let bind = globals(&parents, &iqm.joints.iter().map(|j| j.local).collect::<Vec<_>>());
    let names: Vec<String> = iqm.joints.iter().map(|j| j.name.clone()).collect();
    let rest: Vec<[f64; 3]> = bind.iter().map(|m| [m[0][3], m[1][3], m[2][3]]).collect();
    let rig = bvh::Rig {
        names: &names,
        parents: &parents,
        rest: &rest,
        // Y-up BVH into IQM's Z-up axes (the inverse of `z_up_to_y_up`).
        axes: |p| [p[0], -p[2], p[1]],
    };
    let skins = bvh::retarget(bvh_path, &motion, &rig)?;
    let n = mesh.positions.len();
    let mut vertices = Vec::with_capacity(skins.len() * n);
    for skin in &skins {
        let start = vertices.len();
        skin_frame(&mesh.positions, &infl, skin, &mut vertices);
        for p in &mut vertices[start..] {
            *p = z_up_to_y_up(p.map(f64::from)).map(|x| x as f32);
        }
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        skins.len(),
        n,
        mesh.faces.clone(),
        "",
        path.display().to_string(),
    )?;
    Ok((clip, stats, info.clone()))
}

/// Bytes of a minimal IQM file for tests and fixtures: one mesh of `positions`/`faces` skinned rigidly (weight
/// 255) to the joint in `skin`, joints `(name, parent, translation)`, and one animation of `frames` whose
/// per-frame joint translations are `frames[f][j]` (rotation identity, scale 1). With `mesh = false` only the
/// joints, poses and animation are written (an animation-only file).
#[doc(hidden)]
pub fn write_test_iqm(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    skin: &[u8],
    joints: &[(&str, i32, [f32; 3])],
    anim_name: &str,
    frames: &[Vec<[f32; 3]>],
    mesh: bool,
) -> Vec<u8> {
    let mut text = vec![0u8];
    let mut name = |s: &str| {
        let o = text.len() as u32;
        text.extend(s.as_bytes());
        text.push(0);
        o
    };
    let joint_names: Vec<u32> = joints.iter().map(|j| name(j.0)).collect();
    let anim_name = name(anim_name);
    let mut body: Vec<u8> = Vec::new();
    let put = |body: &mut Vec<u8>, words: &[u32]| words.iter().for_each(|w| body.extend(w.to_le_bytes()));
    let f32s = |body: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| body.extend(x.to_le_bytes()));
    let base = HEADER as u32;
    let ofs_text = base;
    body.extend(&text);
    while !body.len().is_multiple_of(4) {
        body.push(0);
    }
    let (nv, nt) = (positions.len() as u32, faces.len() as u32);
    let mut ofs = [0u32; 6]; // meshes, va, positions, blendidx, blendw, tris
    if mesh {
        ofs[0] = base + body.len() as u32;
        put(&mut body, &[0, 0, 0, nv, 0, nt]);
        ofs[1] = base + body.len() as u32;
        let va_at = body.len();
        body.extend(vec![0u8; 60]);
        ofs[2] = base + body.len() as u32;
        positions.iter().for_each(|p| f32s(&mut body, p));
        ofs[3] = base + body.len() as u32;
        skin.iter().for_each(|&j| body.extend([j, 0, 0, 0]));
        ofs[4] = base + body.len() as u32;
        skin.iter().for_each(|_| body.extend([255u8, 0, 0, 0]));
        ofs[5] = base + body.len() as u32;
        faces.iter().for_each(|f| put(&mut body, &[f[0], f[2], f[1]]));
        let mut va = Vec::new();
        put(&mut va, &[0, 0, 7, 3, ofs[2], 4, 0, 1, 4, ofs[3], 5, 0, 1, 4, ofs[4]]);
        body[va_at..va_at + 60].copy_from_slice(&va);
    }
    let ofs_joints = base + body.len() as u32;
    for (j, (_, parent, t)) in joints.iter().enumerate() {
        put(&mut body, &[joint_names[j], *parent as u32]);
        f32s(&mut body, t);
        f32s(&mut body, &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
    }
    let ofs_poses = base + body.len() as u32;
    for (_, parent, _) in joints {
        put(&mut body, &[*parent as u32, 0b111]);
        f32s(&mut body, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
        f32s(
            &mut body,
            &[1.0 / 64.0, 1.0 / 64.0, 1.0 / 64.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
    }
    let ofs_anims = base + body.len() as u32;
    put(&mut body, &[anim_name, 0, frames.len() as u32]);
    f32s(&mut body, &[24.0]);
    put(&mut body, &[0]);
    let ofs_frames = base + body.len() as u32;
    for f in frames {
        for t in f {
            for c in t {
                body.extend(((c * 64.0).round() as u16).to_le_bytes());
            }
        }
    }
    let size = HEADER as u32 + body.len() as u32;
    let nj = joints.len() as u32;
    let (nm, nva, nvx, ntr) = if mesh { (1, 3, nv, nt) } else { (0, 0, 0, 0) };
    let na = u32::from(!frames.is_empty());
    let mut out = MAGIC.to_vec();
    let header = [
        2,
        size,
        0,
        text.len() as u32,
        ofs_text,
        nm,
        ofs[0],
        nva,
        nvx,
        ofs[1],
        ntr,
        ofs[5],
        0,
        nj,
        ofs_joints,
        nj,
        ofs_poses,
        na,
        ofs_anims,
        frames.len() as u32,
        3 * nj,
        ofs_frames,
        0,
        0,
        0,
        0,
        0,
    ];
    header.iter().for_each(|w| out.extend(w.to_le_bytes()));
    out.extend(body);
    out
}

/// Bytes of an `.iqm` rig for tests and fuzzing, in IQM's Z-up axes: the chain of [`super::bvh::write_test_bvh`]'s skeleton with the arm
/// hanging down (an A-pose), hips at height 10, joints named `names`; vertex 0 sits on the hand, vertices 1 and 2
/// on the hips.
#[doc(hidden)]
pub fn write_test_rig(names: [&str; 8]) -> Vec<u8> {
    let joints = [
        (names[0], -1, [0.0, 0.0, 10.0]),
        (names[1], 0, [0.0, 0.0, 2.0]),
        (names[2], 1, [0.0, 0.0, 2.0]),
        (names[3], 2, [0.0, 0.0, 2.0]),
        (names[4], 3, [0.0, 0.0, 1.0]),
        (names[5], 2, [1.0, 0.0, 0.0]),
        (names[6], 5, [0.0, 0.0, -3.0]),
        (names[7], 6, [0.0, 0.0, -3.0]),
    ];
    let pos = [[1.0, 0.0, 8.0], [0.0, 0.0, 10.0], [0.0, 1.0, 10.0]];
    write_test_iqm(&pos, &[[0, 1, 2]], &[7, 0, 0], &joints, "", &[], true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.0, 1.0]],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn bakes_joint_translation_into_vertices_z_up_to_y_up() {
        let dir = tempfile::tempdir().unwrap();
        let (pos, faces) = quad();
        let joints = [("root", -1, [0.0; 3]), ("top", 0, [0.0, 0.0, 1.0])];
        // Frame f moves the root by (f, 0, 0) and the top joint by an extra 0.5 f in z (local, so on top of root).
        let frames: Vec<Vec<[f32; 3]>> = (0..3)
            .map(|f| vec![[f as f32, 0.0, 0.0], [0.0, 0.0, 1.0 + 0.5 * f as f32]])
            .collect();
        let bytes = write_test_iqm(&pos, &faces, &[0, 0, 1, 1], &joints, "slide", &frames, true);
        let path = dir.path().join("thing.iqm");
        std::fs::write(&path, bytes).unwrap();
        let takes = list_takes(&path).unwrap();
        assert_eq!((takes[0].name.as_str(), takes[0].frames), ("slide", 3));
        let (clip, stats, _) = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!((clip.frames, clip.n_vertices, stats.vertices), (3, 4, 4));
        // Vertex 2 = (1, 0, 1) on the top joint at frame 2: root +2 in x, top +1 in z → (3, 0, 2) → Y-up (3, 2, 0).
        let v = clip.frame(2)[2];
        assert!(
            (v[0] - 3.0).abs() < 1e-5 && (v[1] - 2.0).abs() < 1e-5 && v[2].abs() < 1e-5,
            "{v:?}"
        );
        assert_eq!(clip.frame(0)[0], [0.0, 0.0, 0.0]);
    }

    #[test]
    fn non_finite_and_negative_frame_rates_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let (pos, faces) = quad();
        let joints = [("root", -1, [0.0; 3])];
        let frames = vec![vec![[0.0f32; 3]]; 3];
        let bytes = write_test_iqm(&pos, &faces, &[0; 4], &joints, "slide", &frames, true);
        let rate = 24.0f32.to_le_bytes();
        let at: Vec<usize> = (0..bytes.len() - 3).filter(|&i| bytes[i..i + 4] == rate).collect();
        assert_eq!(at.len(), 1, "the writer's 24 fps is the only such float in this file");
        for bad in [f32::NAN, f32::INFINITY, -24.0, 1e9] {
            let mut b = bytes.clone();
            b[at[0]..at[0] + 4].copy_from_slice(&bad.to_le_bytes());
            let path = dir.path().join("thing.iqm");
            std::fs::write(&path, b).unwrap();
            let e = list_takes(&path).unwrap_err();
            // NaN and infinity already fail the reader's finite-float check; the rate check adds the rest.
            let why = if bad.is_finite() { "frame rate" } else { "non-finite" };
            assert!(e.field == "anims[0]" && e.reason.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn mesh_without_animation_uses_animation_files_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let (pos, faces) = quad();
        let joints = [("root", -1, [0.0; 3])];
        let still = vec![vec![[0.0f32; 3]]; 1];
        let mesh = write_test_iqm(&pos, &faces, &[0; 4], &joints, "", &still[..0], true);
        std::fs::create_dir(dir.path().join("male")).unwrap();
        let mesh_path = dir.path().join("male/body.iqm");
        std::fs::write(&mesh_path, mesh).unwrap();
        let walk: Vec<Vec<[f32; 3]>> = (0..4).map(|f| vec![[0.0, f as f32, 0.0]]).collect();
        std::fs::write(
            dir.path().join("walk_forward.iqm"),
            write_test_iqm(&[], &[], &[], &joints, "Armature", &walk, false),
        )
        .unwrap();
        // A skeleton of another size is not a take of this mesh.
        let other = [("a", -1, [0.0; 3]), ("b", 0, [0.0; 3])];
        std::fs::write(
            dir.path().join("other.iqm"),
            write_test_iqm(&[], &[], &[], &other, "x", &vec![vec![[0.0; 3]; 2]; 3], false),
        )
        .unwrap();
        assert!(!has_mesh(&dir.path().join("walk_forward.iqm")) && has_mesh(&mesh_path));
        let takes = list_takes(&mesh_path).unwrap();
        assert_eq!(takes.len(), 1, "{takes:?}");
        assert_eq!((takes[0].name.as_str(), takes[0].frames), ("walk_forward", 4));
        let (clip, _, _) = read(&mesh_path, &ReadOptions::default()).unwrap();
        // Root moves +3 in IQM y → −3 in Y-up z.
        assert!((clip.frame(3)[0][2] + 3.0).abs() < 1e-5, "{:?}", clip.frame(3)[0]);
    }

    #[test]
    fn refuses_static_meshes_long_takes_and_truncation() {
        let dir = tempfile::tempdir().unwrap();
        let (pos, faces) = quad();
        let joints = [("root", -1, [0.0; 3])];
        let path = dir.path().join("static.iqm");
        std::fs::write(&path, write_test_iqm(&pos, &faces, &[0; 4], &joints, "", &[], true)).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("static mesh is not a clip"), "{e}");

        let frames = vec![vec![[0.0f32; 3]]; 40];
        let bytes = write_test_iqm(&pos, &faces, &[0; 4], &joints, "long", &frames, true);
        std::fs::write(&path, &bytes).unwrap();
        let opts = ReadOptions {
            max_frames: 30,
            ..ReadOptions::default()
        };
        let e = read(&path, &opts).unwrap_err();
        assert!(e.reason.contains("40 frames, more than the maximum of 30"), "{e}");

        // A weight naming a joint the skeleton lacks.
        let bytes = write_test_iqm(&pos, &faces, &[0, 0, 5, 0], &joints, "a", &frames[..2], true);
        std::fs::write(&path, &bytes).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("joint 5"), "{e}");

        for cut in [10, 130, bytes.len() - 3] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            assert!(read(&path, &ReadOptions::default()).is_err(), "cut at {cut}");
        }
    }
}
