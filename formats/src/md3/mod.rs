//! Quake III `.md3` (version 15): per-frame vertex animation of one or more surfaces, `i16` coordinates / 64.
//!
//! Takes: the `lower.md3` of a Quake III player folder (`lower.md3` and `upper.md3` beside an `animation.cfg`)
//! stands for the whole character, assembled through its tags as the game draws it, one take per animation of the
//! cfg ([`player`]); the player's other parts and their coarser copies are not import sources of their own
//! ([`is_source`]), but each reads alone when named. A body part read alone (`lower.md3`, `upper.md3` or a coarser copy
//! such as `upper_1.md3`, with an `animation.cfg` beside it) has the takes that file lists for it ([`cfg_takes`]); any other `.md3` has one
//! take, `all`, holding every frame. All surfaces go into one vertex list; every surface must have the file's
//! frame count. Coordinates go from Z-up to Y-up ([`super::skeletal::z_up_to_y_up`]).
//!
//! Layout (little-endian): 108-byte header (`IDP3`, version, name [64], flags, frame / tag / surface / skin
//! counts, offsets of frames, tags, surfaces, end); tags, frame-major (`name [64]`, origin `f32 × 3`, axis rows
//! `f32 × 9` per tag per frame); each surface: `IDP3`, name [64], flags, frame, shader, vertex and triangle
//! counts, then offsets (from the surface start) of triangles (`i32 × 3`), shaders, texture coordinates, vertices
//! (`i16 x, y, z, u16 normal` per vertex per frame) and the surface's end.

pub mod player;
#[doc(hidden)]
pub mod testing;

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo, z_up_to_y_up};
use crate::clip::Clip;
use crate::error::Result;
use crate::mat3;
pub use player::{ANIMATIONS, MAX_CFG_BYTES, Player, cfg_takes};

/// Most surfaces an MD3 may have (the format's own limit).
const MAX_SURFACES: usize = 32;

/// Most tags an MD3 may have per frame (the format's own limit).
const MAX_TAGS: usize = 16;

/// Bytes of one tag of one frame.
const TAG_BYTES: usize = 112;

struct Surface {
    verts: usize,
    faces: Vec<[u32; 3]>,
    ofs_xyz: usize,
}

struct Md3 {
    frames: usize,
    surfaces: Vec<Surface>,
    tags: usize,
    ofs_tags: usize,
}

/// Where a part is drawn: Quake III's `orientation_t`, an origin and three axis rows; a point `v` of the part
/// lies at `origin + Σ_i v[i]·axis[i]` = `origin + axisᵀ v` (Z-up file coordinates).
#[derive(Debug, Clone, Copy)]
struct Place {
    origin: [f64; 3],
    axis: mat3::Mat3,
}

impl Place {
    const ROOT: Place = Place {
        origin: [0.0; 3],
        axis: mat3::IDENTITY,
    };

    fn point(&self, v: [f64; 3]) -> [f64; 3] {
        mat3::add_scaled(self.origin, mat3::mat_vec(&mat3::transpose(&self.axis), v), 1.0)
    }

    /// The place of a part hung on this one's `tag` (Quake III's `CG_PositionEntityOnTag`): the tag's origin
    /// taken into this place, its axes multiplied by this place's (`tag.axis × axis`).
    fn attach(&self, tag: &Place) -> Place {
        Place {
            origin: self.point(tag.origin),
            axis: mat3::mat_mul(&tag.axis, &self.axis),
        }
    }
}

fn parse(b: &mut Bytes) -> Result<Md3> {
    if b.take(4, "ident").ok() != Some(&b"IDP3"[..]) {
        return Err(b.err("ident", "not an MD3 file (no IDP3 header)"));
    }
    let version = b.i32("version")?;
    if version != 15 {
        return Err(b.err("version", format!("version {version}, only 15 is supported")));
    }
    b.take(64, "name")?;
    let _flags = b.i32("flags")?;
    let frames = b.count_i32("num_frames")?;
    let tags = b.count_i32("num_tags")?;
    let num_surfaces = b.count_i32("num_surfaces")?;
    let _skins = b.count_i32("num_skins")?;
    let _ofs_frames = b.count_i32("ofs_frames")?;
    let ofs_tags = b.count_i32("ofs_tags")?;
    let mut at = b.count_i32("ofs_surfaces")?;
    if num_surfaces > MAX_SURFACES {
        return Err(b.err("num_surfaces", format!("{num_surfaces}, more than {MAX_SURFACES}")));
    }
    if tags > MAX_TAGS {
        return Err(b.err("num_tags", format!("{tags}, more than {MAX_TAGS}")));
    }
    let mut surfaces = Vec::with_capacity(num_surfaces);
    for s in 0..num_surfaces {
        let f = format!("surfaces[{s}]");
        b.seek(at, &f)?;
        if b.take(4, &f)? != b"IDP3" {
            return Err(b.err(&f, "surface does not start with IDP3"));
        }
        b.take(64, &f)?;
        let _flags = b.i32(&f)?;
        let nf = b.count_i32(&f)?;
        let _shaders = b.count_i32(&f)?;
        let nv = b.count_i32(&f)?;
        let nt = b.count_i32(&f)?;
        let ofs_tris = b.count_i32(&f)?;
        let _ofs_shaders = b.count_i32(&f)?;
        let _ofs_st = b.count_i32(&f)?;
        let ofs_xyz = b.count_i32(&f)?;
        let ofs_end = b.count_i32(&f)?;
        if nf != frames {
            return Err(b.err(&f, format!("{nf} frames, the file has {frames}")));
        }
        let per_frame = nv.checked_mul(8).ok_or_else(|| b.err(&f, "vertex count overflows"))?;
        b.check_count_at(at + ofs_xyz, frames, per_frame, &f)?;
        b.check_count_at(at + ofs_tris, nt, 12, &f)?;
        b.seek(at + ofs_tris, &f)?;
        let mut faces = Vec::with_capacity(nt);
        for t in 0..nt {
            let tri = [b.u32(&f)?, b.u32(&f)?, b.u32(&f)?];
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= nv) {
                return Err(b.err(format!("{f}.triangles[{t}]"), format!("vertex {i} of {nv}")));
            }
            // Quake winds clockwise; the clip convention is counter-clockwise.
            faces.push([tri[0], tri[2], tri[1]]);
        }
        surfaces.push(Surface {
            verts: nv,
            faces,
            ofs_xyz: at + ofs_xyz,
        });
        if ofs_end == 0 {
            return Err(b.err(&f, "surface end offset is 0"));
        }
        at = at
            .checked_add(ofs_end)
            .ok_or_else(|| b.err(&f, "surface end offset overflows"))?;
    }
    let m = Md3 {
        frames,
        surfaces,
        tags,
        ofs_tags,
    };
    // Frames of vertices are counted by the file's length; a file without vertices could claim any number.
    if m.vertices() == 0 {
        return Err(b.err("num_surfaces", "no vertices"));
    }
    Ok(m)
}

impl Md3 {
    fn vertices(&self) -> usize {
        self.surfaces.iter().map(|s| s.verts).sum()
    }

    /// Every surface's triangles in one list, vertex indices moved up by `base`.
    fn faces(&self, base: u32) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        let mut at = base;
        for s in &self.surfaces {
            out.extend(s.faces.iter().map(|f| f.map(|i| i + at)));
            at += s.verts as u32;
        }
        out
    }
}

/// One `.md3` read and parsed: its path as text (for errors), header and surfaces, and its bytes.
struct Md3File {
    path: String,
    md3: Md3,
    data: Vec<u8>,
}

impl Md3File {
    fn open(path: &Path) -> Result<Md3File> {
        let data = super::read_clip_file(path)?;
        let path = path.display().to_string();
        let md3 = parse(&mut Bytes::new(&path, &data))?;
        Ok(Md3File { path, md3, data })
    }

    fn bytes(&self) -> Bytes<'_> {
        Bytes::new(&self.path, &self.data)
    }

    /// The vertices of frame `f` (in range), all surfaces in order, in Z-up file units, appended to `out`.
    fn points(&self, f: usize, out: &mut Vec<[f64; 3]>) -> Result<()> {
        let mut b = self.bytes();
        for (k, s) in self.md3.surfaces.iter().enumerate() {
            b.seek(s.ofs_xyz + f * s.verts * 8, &format!("surfaces[{k}].xyz"))?;
            for _ in 0..s.verts {
                out.push([b.i16("xyz")?, b.i16("xyz")?, b.i16("xyz")?].map(|c| c as f64 / 64.0));
                b.u16("normal")?;
            }
        }
        Ok(())
    }

    /// Index of the tag named `name` (compared exactly, as the game's `strcmp` does), every frame's tags checked to
    /// lie inside the file; an error when there is none.
    fn tag_index(&self, name: &str) -> Result<usize> {
        let (m, mut b) = (&self.md3, self.bytes());
        let count = m
            .frames
            .checked_mul(m.tags)
            .ok_or_else(|| b.err("num_tags", "frames × tags overflows"))?;
        b.check_count_at(m.ofs_tags, count, TAG_BYTES, "tags")?;
        for t in 0..m.tags {
            b.seek(m.ofs_tags + t * TAG_BYTES, "tags")?;
            if b.name(64, "tags")? == name {
                return Ok(t);
            }
        }
        Err(b.err("tags", format!("no {name}: the part hung on it cannot be placed")))
    }

    /// Tag `t` (from [`Md3File::tag_index`]) at frame `f` (in range).
    fn tag(&self, t: usize, f: usize) -> Result<Place> {
        let (m, mut b) = (&self.md3, self.bytes());
        b.seek(m.ofs_tags + (f * m.tags + t) * TAG_BYTES + 64, "tags")?;
        let origin = b.f32s::<3>("tags")?.map(f64::from);
        let a = b.f32s::<9>("tags")?.map(f64::from);
        Ok(Place {
            origin,
            axis: [[a[0], a[1], a[2]], [a[3], a[4], a[5]], [a[6], a[7], a[8]]],
        })
    }
}

/// Whether an import reads `path` as a clip: not when it is a part of a player folder other than its
/// `lower.md3` (the upper body, the head and the coarser copies belong to the character the `lower.md3` stands
/// for).
pub fn is_source(path: &Path) -> bool {
    match Player::beside(path) {
        Some(p) => !player::is_part_name(path) || p.lower.file_name() == path.file_name(),
        None => true,
    }
}

/// The takes of an `.md3` with `frames` frames read alone: from the player's `animation.cfg`, else `all`.
fn ranges(path: &Path, frames: usize) -> Result<Vec<player::Range>> {
    if let Some(r) = player::part_ranges(path, frames)? {
        return Ok(r);
    }
    Ok(skeletal::single_take(frames)
        .into_iter()
        .map(|info| player::Range {
            frames: (0..info.frames).collect(),
            info,
        })
        .collect())
}

/// The takes of an `.md3`: the assembled player's animations for a player's `lower.md3`, a body part's from its
/// `animation.cfg`, else `all` when it has at least 2 frames.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    if let Some(p) = Player::of(path) {
        return player::list_player_takes(&p);
    }
    let frames = Md3File::open(path)?.md3.frames;
    Ok(ranges(path, frames)?.into_iter().map(|r| r.info).collect())
}

/// The one-frame animations (poses, not takes) of a player's or body part's `animation.cfg`, by name; none for
/// any other `.md3`.
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    if let Some(p) = Player::of(path) {
        return player::one_frame_animations(&p.cfg, None);
    }
    match player::part_cfg(path) {
        Some((cfg, part)) => player::one_frame_animations(&cfg, Some(part)),
        None => Ok(Vec::new()),
    }
}

/// Read take `opts.take` of an `.md3` as a clip (id = file stem, or the player's folder for an assembled
/// player; caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    if let Some(p) = Player::of(path) {
        return player::read_player(&p, opts);
    }
    let part = Md3File::open(path)?;
    let m = &part.md3;
    let takes = ranges(path, m.frames)?;
    let infos: Vec<TakeInfo> = takes.iter().map(|r| r.info.clone()).collect();
    let take = &takes[skeletal::pick(path, &infos, &opts.take)?];
    let info = take.info.clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    let n = m.vertices();
    skeletal::check_rows(path, info.frames, n)?;
    let mut vertices = Vec::with_capacity(info.frames * n);
    let mut points = Vec::new();
    for &f in &take.frames {
        points.clear();
        part.points(f, &mut points)?;
        vertices.extend(points.iter().map(|&p| z_up_to_y_up(p).map(|x| x as f32)));
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        info.frames,
        n,
        m.faces(0),
        "",
        part.path.clone(),
    )?;
    Ok((clip, SkinStats::default(), info))
}

/// Bytes of a one-surface MD3 for tests: `frames[f][v]` in 1/64 units.
#[doc(hidden)]
pub fn write_test_md3(frames: &[Vec<[i16; 3]>], faces: &[[u32; 3]]) -> Vec<u8> {
    write_test_md3_tags(frames, faces, &[])
}

/// A test tag: its name and, per frame, its origin and axis rows.
#[doc(hidden)]
pub type TestTag<'a> = (&'a str, Vec<([f32; 3], [[f32; 3]; 3])>);

/// [`write_test_md3`] with tags (each with one place per frame).
#[doc(hidden)]
pub fn write_test_md3_tags(frames: &[Vec<[i16; 3]>], faces: &[[u32; 3]], tags: &[TestTag]) -> Vec<u8> {
    let nv = frames.first().map_or(0, Vec::len);
    let i = |out: &mut Vec<u8>, x: usize| out.extend((x as i32).to_le_bytes());
    let mut out = b"IDP3".to_vec();
    i(&mut out, 15);
    out.extend([0u8; 64]);
    let surface = 108 + TAG_BYTES * tags.len() * frames.len();
    for x in [0, frames.len(), tags.len(), 1, 0, 108, 108, surface] {
        i(&mut out, x);
    }
    let ofs_tris = 108;
    let ofs_xyz = ofs_tris + 12 * faces.len();
    let end = ofs_xyz + 8 * nv * frames.len();
    i(&mut out, end + surface); // file end
    for f in 0..frames.len() {
        for (name, places) in tags {
            let mut field = [0u8; 64];
            field[..name.len()].copy_from_slice(name.as_bytes());
            out.extend(field);
            let (origin, axis) = places[f];
            origin
                .iter()
                .chain(axis.iter().flatten())
                .for_each(|x| out.extend(x.to_le_bytes()));
        }
    }
    out.extend(b"IDP3");
    out.extend([0u8; 64]);
    for x in [
        0,
        frames.len(),
        0,
        nv,
        faces.len(),
        ofs_tris,
        ofs_xyz,
        ofs_xyz,
        ofs_xyz,
        end,
    ] {
        i(&mut out, x);
    }
    faces
        .iter()
        .for_each(|t| [t[0], t[2], t[1]].iter().for_each(|&x| i(&mut out, x as usize)));
    for f in frames {
        for v in f {
            v.iter().chain(&[0]).for_each(|c| out.extend(c.to_le_bytes()));
        }
    }
    out
}

#[cfg(test)]
mod tests;
