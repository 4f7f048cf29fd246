//! SuperTuxKart `.spm` meshes (karts with their drivers, track characters and props), baked from their armatures.
//!
//! Layout (little-endian, as the game's mesh loader reads it): `"SP"`, a byte `version << 3 | kind` (version 1;
//! kind 1 animated, 0 a space-partitioned track mesh (refused), anything else static), a flags byte (1 normals,
//! 2 vertex colours, 4 tangents), a bounding box (f32×6), `u16` materials of two texture names (`u8` length each),
//! then `u16` sectors of `u16` buffers, each `vertices u32 | indices u32 | material u16`, its vertices and its
//! indices (`u8` when the buffer has at most 255 vertices, else `u16`; at most 65,535 vertices per buffer). A
//! vertex is `position f32×3`, a packed normal (4 bytes) when flagged, a colour when flagged (`u8` 128 = white,
//! else 3 more bytes), two half-float texture coordinates when its material names a first texture (2 more when it
//! names a second, then a packed tangent when flagged), and in an animated file `joint i16×4 | weight f16×4`.
//! An animated file ends with `u8` armatures and a `u16` bind frame, then per armature `used u16 | joints u16`,
//! the joint names (`u8` length), inverse bind transforms (loc f32×3, rotation x y z w f32×4, scale f32×3; unused,
//! as by the game), parents (`i16`, −1 for a root, in any order) and `u16` key frames of `frame u16` with one
//! loc / rotation / scale per joint, relative to its parent.
//!
//! Baking (the game's skinning): a joint's local transform at frame f is T·R·S of its keys (location and scale
//! linear, rotation spherical between the surrounding key frames, held outside them) and `G_f` its product along
//! the parent chain. The file's vertices are posed at the bind frame, so `v_f = Σ_i w_i · G_f(j_i) · G_bind(j_i)⁻¹ ·
//! v_file` (docs/method.md's linear blend skinning with the bind frame as the rest pose). Vertex joint `i` is the
//! `i`-th used joint counting through the armatures in order (the first `used` joints of each); a vertex whose
//! first joint is −1 or whose first weight is 0 does not move. The take, `all`, is every integer frame from the
//! first to the last key frame of any armature (the game's frame rate is set per object, not in the file: 0).
//!
//! The game's space is left-handed, y up: positions are mirrored to right-handed y-up coordinates,
//! `(x, y, z) → (x, y, −z)`, with each triangle's winding reversed (as for B3D).

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{
    self, IDENTITY, Influences, Mat, ReadOptions, SkinStats, TakeInfo, clean_influences, inverse, lerp3, mul,
    normalize_quat, skin_frame, slerp, trs,
};
use crate::error::{DataError, Result};

/// The one version the game reads.
const VERSION: u8 = 1;
/// Most vertices in one buffer (indices are 16-bit).
const MAX_BUFFER_VERTICES: usize = 65_535;

/// A joint's location, rotation (x y z w) and scale.
#[derive(Clone, Copy)]
struct Lrs {
    loc: [f64; 3],
    rot: [f64; 4],
    scale: [f64; 3],
}

impl Lrs {
    fn read(b: &mut Bytes, field: &str) -> Result<Self> {
        let v = b.f32s::<10>(field)?.map(f64::from);
        Ok(Self {
            loc: [v[0], v[1], v[2]],
            rot: normalize_quat([v[3], v[4], v[5], v[6]]),
            scale: [v[7], v[8], v[9]],
        })
    }

    fn lerp(&self, other: &Self, t: f64) -> Self {
        Self {
            loc: lerp3(self.loc, other.loc, t),
            rot: slerp(self.rot, other.rot, t),
            scale: lerp3(self.scale, other.scale, t),
        }
    }
}

struct Armature {
    used: usize,
    parents: Vec<Option<usize>>,
    /// Joints with every parent before its children.
    order: Vec<usize>,
    /// (frame, one transform per joint), sorted by frame.
    keys: Vec<(i64, Vec<Lrs>)>,
}

impl Armature {
    /// Object-space transforms of every joint at `frame`.
    fn globals(&self, frame: i64) -> Vec<Mat> {
        let after = self.keys.partition_point(|(k, _)| *k <= frame);
        let pose = |j: usize| match (after.checked_sub(1).map(|i| &self.keys[i]), self.keys.get(after)) {
            (Some((k0, a)), Some((k1, b))) => a[j].lerp(&b[j], (frame - k0) as f64 / (k1 - k0) as f64),
            (Some((_, a)), None) | (None, Some((_, a))) => a[j],
            (None, None) => unreachable!("an armature has key frames (checked when read)"),
        };
        let mut g = vec![IDENTITY; self.parents.len()];
        for &j in &self.order {
            let p = pose(j);
            let local = trs(p.loc, p.rot, p.scale);
            g[j] = match self.parents[j] {
                Some(parent) => mul(&g[parent], &local),
                None => local,
            };
        }
        g
    }
}

struct Spm {
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    /// Per vertex (joint, weight) pairs as the file gives them; `None` for a vertex that does not move.
    weights: Vec<Option<[(i16, f32); 4]>>,
    bind_frame: i64,
    armatures: Vec<Armature>,
}

/// A `u8`-length name.
fn short_name(b: &mut Bytes, field: &str) -> Result<String> {
    let n = usize::from(b.u8(field)?);
    Ok(String::from_utf8_lossy(b.take(n, field)?).into_owned())
}

fn parse(path: &Path) -> Result<Spm> {
    let data = super::read_clip_file(path)?;
    let p = path.display().to_string();
    let mut b = Bytes::new(&p, &data);
    if b.take(2, "magic").ok() != Some(&b"SP"[..]) {
        return Err(b.err("magic", "not a SuperTuxKart mesh (no SP header)"));
    }
    let head = b.u8("version")?;
    if head >> 3 != VERSION {
        return Err(b.err("version", format!("version {}, only {VERSION} is supported", head >> 3)));
    }
    let animated = match head & 0x07 {
        0 => {
            return Err(b.err(
                "kind",
                "a space-partitioned track mesh, which the game itself no longer reads",
            ));
        }
        1 => true,
        _ => false,
    };
    let flags = b.u8("flags")?;
    let (normals, colours, tangents) = (flags & 1 != 0, flags & 2 != 0, flags & 4 != 0);
    b.take(24, "bounding_box")?;
    let n_materials = usize::from(b.u16("materials")?);
    b.check_count(n_materials, 2, "materials")?;
    let mut materials = Vec::with_capacity(n_materials);
    for m in 0..n_materials {
        let f = format!("materials[{m}]");
        let first = !short_name(&mut b, &f)?.is_empty();
        let second = !short_name(&mut b, &f)?.is_empty();
        materials.push((first, second));
    }
    let mut file = Spm {
        positions: Vec::new(),
        faces: Vec::new(),
        weights: Vec::new(),
        bind_frame: 0,
        armatures: Vec::new(),
    };
    let sectors = b.u16("sectors")?;
    for s in 0..sectors {
        let buffers = b.u16(&format!("sectors[{s}]"))?;
        for k in 0..buffers {
            let f = format!("sectors[{s}].buffers[{k}]");
            let vertices = b.usize(&f)?;
            let indices = b.usize(&f)?;
            let material = usize::from(b.u16(&f)?);
            let &(uv, uv2) = materials
                .get(material)
                .ok_or_else(|| b.err(&f, format!("material {material} of {n_materials}")))?;
            if vertices == 0 || vertices > MAX_BUFFER_VERTICES {
                return Err(b.err(&f, format!("{vertices} vertices (1 to {MAX_BUFFER_VERTICES})")));
            }
            if indices == 0 || !indices.is_multiple_of(3) {
                return Err(b.err(&f, format!("{indices} indices are not whole triangles")));
            }
            b.check_count(vertices, 12, &f)?;
            let base = file.positions.len();
            for v in 0..vertices {
                let fv = format!("{f}.vertices[{v}]");
                file.positions.push(b.f32s::<3>(&fv)?.map(f64::from));
                b.take(if normals { 4 } else { 0 }, &fv)?;
                let colour = if colours && b.u8(&fv)? != 128 { 3 } else { 0 };
                let uvs = if uv {
                    4 + if uv2 { 4 } else { 0 } + if tangents { 4 } else { 0 }
                } else {
                    0
                };
                b.take(colour + uvs, &fv)?;
                file.weights.push(if animated { skin(&mut b, &fv)? } else { None });
            }
            let wide = vertices > 255;
            b.check_count(indices, if wide { 2 } else { 1 }, &f)?;
            let mut tri = [0u32; 3];
            for i in 0..indices {
                let index = if wide {
                    usize::from(b.u16(&f)?)
                } else {
                    usize::from(b.u8(&f)?)
                };
                if index >= vertices {
                    return Err(b.err(&f, format!("index {index} of a buffer of {vertices} vertices")));
                }
                tri[i % 3] = (base + index) as u32;
                if i % 3 == 2 {
                    file.faces.push(tri);
                }
            }
        }
    }
    if animated {
        armatures(&mut b, &mut file)?;
    }
    Ok(file)
}

/// A vertex's four (joint, weight) pairs, `None` when it does not move (first joint −1 or first weight ±0).
fn skin(b: &mut Bytes, field: &str) -> Result<Option<[(i16, f32); 4]>> {
    let mut pairs = [(0i16, 0f32); 4];
    for p in &mut pairs {
        p.0 = b.i16(field)?;
    }
    for p in &mut pairs {
        p.1 = half::f16::from_bits(b.u16(field)?).to_f32();
    }
    Ok((pairs[0].0 != -1 && pairs[0].1 != 0.0).then_some(pairs))
}

fn armatures(b: &mut Bytes, file: &mut Spm) -> Result<()> {
    let n = usize::from(b.u8("armatures")?);
    if n == 0 {
        return Err(b.err("armatures", "an animated mesh without an armature"));
    }
    file.bind_frame = i64::from(b.u16("bind_frame")?);
    for a in 0..n {
        let f = format!("armatures[{a}]");
        let used = usize::from(b.u16(&f)?);
        let joints = usize::from(b.u16(&f)?);
        if used == 0 || joints == 0 || used > joints || joints > skeletal::MAX_JOINTS {
            return Err(b.err(
                &f,
                format!(
                    "{used} used of {joints} joints (1 ≤ used ≤ joints ≤ {})",
                    skeletal::MAX_JOINTS
                ),
            ));
        }
        for j in 0..joints {
            short_name(b, &format!("{f}.names[{j}]"))?;
        }
        let bind = b.check_count(joints, 40, &f)? * 40;
        b.take(bind, &format!("{f}.bind"))?;
        b.check_count(joints, 2, &f)?;
        let mut parents = Vec::with_capacity(joints);
        for j in 0..joints {
            let p = b.i16(&format!("{f}.parents[{j}]"))?;
            parents.push(match usize::try_from(p) {
                Ok(p) if p < joints && p != j => Some(p),
                Err(_) if p == -1 => None,
                _ => return Err(b.err(format!("{f}.parents[{j}]"), format!("parent {p} of {joints} joints"))),
            });
        }
        let order = parent_order(&parents).ok_or_else(|| b.err(format!("{f}.parents"), "the parents form a cycle"))?;
        let frames = usize::from(b.u16(&format!("{f}.frames"))?);
        if frames == 0 {
            return Err(b.err(format!("{f}.frames"), "an armature without key frames"));
        }
        let size = 40usize
            .checked_mul(joints)
            .and_then(|s| s.checked_add(2))
            .unwrap_or(usize::MAX);
        b.check_count(frames, size, &format!("{f}.frames"))?;
        let mut keys = Vec::with_capacity(frames);
        for k in 0..frames {
            let fk = format!("{f}.frames[{k}]");
            let frame = i64::from(b.u16(&fk)?);
            let pose = (0..joints).map(|_| Lrs::read(b, &fk)).collect::<Result<Vec<_>>>()?;
            keys.push((frame, pose));
        }
        keys.sort_by_key(|k| k.0);
        file.armatures.push(Armature {
            used,
            parents,
            order,
            keys,
        });
    }
    Ok(())
}

/// The joints ordered so that every parent precedes its children; `None` when the parents form a cycle.
fn parent_order(parents: &[Option<usize>]) -> Option<Vec<usize>> {
    let n = parents.len();
    let mut depth = vec![usize::MAX; n];
    for start in 0..n {
        // Walk up to a root or to a joint whose depth is known; a walk longer than the skeleton is a cycle.
        let (mut chain, mut at, mut base) = (Vec::new(), Some(start), 0);
        while let Some(j) = at {
            if depth[j] != usize::MAX {
                base = depth[j] + 1;
                break;
            }
            if chain.len() >= n {
                return None;
            }
            chain.push(j);
            at = parents[j];
        }
        for (i, &j) in chain.iter().rev().enumerate() {
            depth[j] = base + i;
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&j| depth[j]);
    Some(order)
}

/// The frames the armatures' keys span: (first, last).
fn key_range(armatures: &[Armature]) -> Option<(i64, i64)> {
    let first = armatures.iter().filter_map(|a| a.keys.first().map(|k| k.0)).min()?;
    let last = armatures.iter().filter_map(|a| a.keys.last().map(|k| k.0)).max()?;
    Some((first, last))
}

/// Largest XML file read for a mesh's frame ranges, in bytes.
const MAX_XML_BYTES: u64 = 16 << 20;

/// The frame ranges the game plays from `path`, from an XML file beside it that names it: a kart's `kart.xml`
/// (`model-file`; the marks of its `animations` element, each running to the next mark or to `last`, a mark named
/// `end-…` closing an animation rather than opening one) or a library object's `node.xml` / a track's `scene.xml`
/// (the `frame-start` and `frame-end` lists of an element whose `model` is the mesh). Empty when none says.
fn game_ranges(path: &Path, last: i64) -> Result<Vec<(String, i64, i64)>> {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return Ok(Vec::new());
    };
    for xml in skeletal::companions(path, &["xml"], false) {
        let text = super::read_text_file(&xml, MAX_XML_BYTES)?;
        if !text.contains(&name) {
            continue;
        }
        let doc = roxmltree::Document::parse(&text).map_err(|e| DataError::new(&xml, "xml", e.to_string()))?;
        let frame = |node: roxmltree::Node, attr: &str, v: &str| {
            v.parse::<u16>().map(i64::from).map_err(|_| {
                DataError::new(
                    &xml,
                    format!("{}.{attr}", node.tag_name().name()),
                    format!("{v:?} is not a frame"),
                )
            })
        };
        let mut ranges = Vec::new();
        for node in doc.descendants().filter(|n| n.is_element()) {
            if node.attribute("model-file") == Some(&name)
                && let Some(anim) = node.children().find(|c| c.has_tag_name("animations"))
            {
                let mut marks = anim
                    .attributes()
                    .map(|a| Ok((frame(anim, a.name(), a.value())?, a.name().to_owned())))
                    .collect::<Result<Vec<_>>>()?;
                marks.sort();
                for (i, (start, mark)) in marks.iter().enumerate() {
                    let end = marks.get(i + 1).map_or(last, |m| m.0);
                    if !mark.starts_with("end-") {
                        ranges.push((mark.clone(), *start, end));
                    }
                }
            }
            if node.attribute("model") == Some(&name)
                && let (Some(starts), Some(ends)) = (node.attribute("frame-start"), node.attribute("frame-end"))
            {
                let starts = starts.split_whitespace().map(|v| frame(node, "frame-start", v));
                let ends = ends.split_whitespace().map(|v| frame(node, "frame-end", v));
                for (start, end) in starts.zip(ends) {
                    let (start, end) = (start?, end?);
                    ranges.push((format!("{start}-{end}"), start, end));
                }
            }
        }
        if !ranges.is_empty() {
            ranges.retain(|(_, start, end)| end > start);
            return Ok(ranges);
        }
    }
    Ok(Vec::new())
}

/// The takes of `file` read from `path` with their first frames: the game's frame ranges when an XML file beside
/// it gives them ([`game_ranges`]), else one take of every key frame; none for a static mesh.
fn takes(path: &Path, file: &Spm) -> Result<Vec<(TakeInfo, i64)>> {
    let Some((first, last)) = key_range(&file.armatures) else {
        return Ok(Vec::new());
    };
    let ranges = game_ranges(path, last)?;
    if ranges.is_empty() {
        let all = skeletal::single_take((last - first + 1) as usize);
        return Ok(all.into_iter().map(|t| (t, first)).collect());
    }
    let take = |(name, start, end): (String, i64, i64)| {
        let frames = (end - start + 1) as usize;
        (
            TakeInfo {
                name,
                frames,
                fps: 0.0,
                file: None,
            },
            start,
        )
    };
    Ok(ranges.into_iter().map(take).collect())
}

/// The file's takes: the game's frame ranges from an XML file beside it that names it (a kart's `kart.xml`, a
/// library object's `node.xml`), else one take of every key frame; none for a static mesh.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let file = parse(path)?;
    Ok(takes(path, &file)?.into_iter().map(|(t, _)| t).collect())
}

/// Bake the take of a `.spm` into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(crate::clip::Clip, SkinStats, TakeInfo)> {
    let file = parse(path)?;
    let all = takes(path, &file)?;
    let infos: Vec<TakeInfo> = all.iter().map(|(t, _)| t.clone()).collect();
    let (info, first) = all[skeletal::pick(path, &infos, &opts.take)?].clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    // Joint `i` of a vertex is the `i`-th used joint through the armatures; one more, the identity, holds the
    // vertices that do not move.
    let used: Vec<(usize, usize)> = file
        .armatures
        .iter()
        .enumerate()
        .flat_map(|(a, arm)| (0..arm.used).map(move |j| (a, j)))
        .collect();
    let still = used.len();
    let mut infl: Influences = file
        .weights
        .iter()
        .map(|w| match w {
            None => vec![(still, 1.0)],
            Some(pairs) => pairs
                .iter()
                .filter(|(j, w)| *j >= 0 && *w != 0.0)
                .map(|&(j, w)| (j as usize, f64::from(w)))
                .collect(),
        })
        .collect();
    for (v, (list, w)) in infl.iter().zip(&file.weights).enumerate() {
        if let (Some(_), Some(&(j, _))) = (w, list.iter().find(|(j, _)| *j >= still)) {
            return Err(DataError::new(
                path,
                "weights",
                format!("vertex {v} is weighted to joint {j}, but the armatures use {still} joints"),
            ));
        }
    }
    let stats = clean_influences(path, "weights", &mut infl, still + 1)?;
    let skin_at = |frame: i64| -> Vec<Mat> {
        let g: Vec<Vec<Mat>> = file.armatures.iter().map(|a| a.globals(frame)).collect();
        used.iter().map(|&(a, j)| g[a][j]).chain([IDENTITY]).collect()
    };
    let bind = skin_at(file.bind_frame);
    let inv_bind = used
        .iter()
        .zip(&bind)
        .map(|(&(a, j), m)| {
            inverse(m).ok_or_else(|| {
                DataError::new(
                    path,
                    format!("armatures[{a}].joints[{j}]"),
                    "singular transform at the bind frame",
                )
            })
        })
        .chain([Ok(IDENTITY)])
        .collect::<Result<Vec<Mat>>>()?;
    let n = file.positions.len();
    skeletal::check_rows(path, info.frames, n)?;
    let mut vertices = Vec::with_capacity(info.frames * n);
    for f in 0..info.frames {
        let skin: Vec<Mat> = skin_at(first + f as i64)
            .iter()
            .zip(&inv_bind)
            .map(|(g, inv)| mul(g, inv))
            .collect();
        skin_frame(&file.positions, &infl, &skin, &mut vertices);
    }
    let faces = skeletal::to_right_handed(&mut vertices, file.faces);
    let clip = skeletal::baked_clip(path, vertices, info.frames, faces)?;
    Ok((clip, stats, info))
}

/// Bytes of an animated `.spm` for tests: one buffer (normals and colours flagged, a textured material, so that
/// every optional vertex field is present; every other vertex not white), one armature whose joints are
/// `(name, parent)` with the first `used` of them used, vertex `v` on joint `skin[v]` (255: a vertex that does not
/// move), and per key frame `(frame, one translation per joint)` with identity rotations and unit scales.
#[doc(hidden)]
pub fn write_test_spm(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    skin: &[u8],
    joints: &[(&str, i16)],
    used: u16,
    keys: &[(u16, Vec<[f32; 3]>)],
) -> Vec<u8> {
    let mut out = b"SP".to_vec();
    out.push(VERSION << 3 | 1);
    out.push(1 | 2);
    out.extend([0u8; 24]);
    out.extend(1u16.to_le_bytes());
    out.extend([5, b't', b'.', b'p', b'n', b'g', 0]);
    out.extend(1u16.to_le_bytes());
    out.extend(1u16.to_le_bytes());
    out.extend((positions.len() as u32).to_le_bytes());
    out.extend((faces.len() as u32 * 3).to_le_bytes());
    out.extend(0u16.to_le_bytes());
    for (v, p) in positions.iter().enumerate() {
        p.iter().for_each(|x| out.extend(x.to_le_bytes()));
        out.extend([0u8; 4]);
        if v % 2 == 0 {
            out.push(128);
        } else {
            out.extend([7, 1, 2, 3]);
        }
        out.extend([0u8; 4]);
        let joint = if skin[v] == 255 { -1 } else { i16::from(skin[v]) };
        [joint, -1, -1, -1].iter().for_each(|j| out.extend(j.to_le_bytes()));
        [1.0f32, 0.0, 0.0, 0.0]
            .iter()
            .for_each(|w| out.extend(half::f16::from_f32(*w).to_bits().to_le_bytes()));
    }
    let wide = positions.len() > 255;
    for &i in faces.iter().flatten() {
        if wide {
            out.extend((i as u16).to_le_bytes());
        } else {
            out.push(i as u8);
        }
    }
    out.push(1);
    out.extend(0u16.to_le_bytes());
    out.extend(used.to_le_bytes());
    out.extend((joints.len() as u16).to_le_bytes());
    for (name, _) in joints {
        out.push(name.len() as u8);
        out.extend(name.as_bytes());
    }
    let lrs = |out: &mut Vec<u8>, t: [f32; 3]| {
        [t[0], t[1], t[2], 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]
            .iter()
            .for_each(|x| out.extend(x.to_le_bytes()));
    };
    joints.iter().for_each(|_| lrs(&mut out, [0.0; 3]));
    joints.iter().for_each(|(_, p)| out.extend(p.to_le_bytes()));
    out.extend((keys.len() as u16).to_le_bytes());
    for (frame, translations) in keys {
        out.extend(frame.to_le_bytes());
        translations.iter().for_each(|&t| lrs(&mut out, t));
    }
    out
}

#[cfg(test)]
mod tests;
