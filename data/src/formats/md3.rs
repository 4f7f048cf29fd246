//! Quake III `.md3` (version 15): per-frame vertex animation of one or more surfaces, `i16` coordinates / 64.
//!
//! One take, `all`, holding every frame (the frame ranges of a Quake III player live in a separate
//! `animation.cfg`, which is not read). All surfaces go into one vertex list; every surface must have the file's
//! frame count. Coordinates go from Z-up to Y-up ([`super::skeletal::z_up_to_y_up`]).
//!
//! Layout (little-endian): 108-byte header (`IDP3`, version, name [64], flags, frame / tag / surface / skin
//! counts, offsets of frames, tags, surfaces, end); each surface: `IDP3`, name [64], flags, frame, shader,
//! vertex and triangle counts, then offsets (from the surface start) of triangles (`i32 × 3`), shaders,
//! texture coordinates, vertices (`i16 x, y, z, u16 normal` per vertex per frame) and the surface's end.

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo, z_up_to_y_up};
use crate::clip::Clip;
use crate::error::Result;

/// Most surfaces an MD3 may have (the format's own limit).
const MAX_SURFACES: usize = 32;

struct Surface {
    verts: usize,
    faces: Vec<[u32; 3]>,
    ofs_xyz: usize,
}

struct Md3 {
    frames: usize,
    surfaces: Vec<Surface>,
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
    let _tags = b.count_i32("num_tags")?;
    let num_surfaces = b.count_i32("num_surfaces")?;
    let _skins = b.count_i32("num_skins")?;
    let _ofs_frames = b.count_i32("ofs_frames")?;
    let _ofs_tags = b.count_i32("ofs_tags")?;
    let mut at = b.count_i32("ofs_surfaces")?;
    if num_surfaces > MAX_SURFACES {
        return Err(b.err("num_surfaces", format!("{num_surfaces}, more than {MAX_SURFACES}")));
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
    Ok(Md3 { frames, surfaces })
}

/// The takes of an `.md3`: `all` when it has at least 2 frames.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    Ok(skeletal::single_take(parse(&mut Bytes::new(&s, &data))?.frames))
}

/// Read the frames of an `.md3` as a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    let mut b = Bytes::new(&s, &data);
    let m = parse(&mut b)?;
    let info = skeletal::pick_single(path, m.frames, opts)?;
    let n: usize = m.surfaces.iter().map(|s| s.verts).sum();
    let mut faces = Vec::new();
    let mut base = 0u32;
    for s in &m.surfaces {
        faces.extend(s.faces.iter().map(|f| f.map(|i| i + base)));
        base += s.verts as u32;
    }
    let mut vertices = Vec::with_capacity(m.frames * n);
    for f in 0..m.frames {
        for (k, s) in m.surfaces.iter().enumerate() {
            b.seek(s.ofs_xyz + f * s.verts * 8, &format!("surfaces[{k}].xyz"))?;
            for _ in 0..s.verts {
                let p = [b.i16("xyz")?, b.i16("xyz")?, b.i16("xyz")?].map(|c| c as f64 / 64.0);
                b.u16("normal")?;
                vertices.push(z_up_to_y_up(p).map(|x| x as f32));
            }
        }
    }
    let clip = Clip::new(skeletal::stem(path), vertices, m.frames, n, faces, "", s.clone())?;
    Ok((clip, SkinStats::default(), info))
}

/// Bytes of a one-surface MD3 for tests: `frames[f][v]` in 1/64 units.
#[doc(hidden)]
pub fn write_test_md3(frames: &[Vec<[i16; 3]>], faces: &[[u32; 3]]) -> Vec<u8> {
    let nv = frames.first().map_or(0, Vec::len);
    let i = |out: &mut Vec<u8>, x: usize| out.extend((x as i32).to_le_bytes());
    let mut out = b"IDP3".to_vec();
    i(&mut out, 15);
    out.extend([0u8; 64]);
    for x in [0, frames.len(), 0, 1, 0, 108, 108, 108] {
        i(&mut out, x);
    }
    let ofs_tris = 108;
    let ofs_xyz = ofs_tris + 12 * faces.len();
    let end = ofs_xyz + 8 * nv * frames.len();
    i(&mut out, end + 108); // file end
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
mod tests {
    use super::*;

    #[test]
    fn reads_frames_and_refuses_bad_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flag.md3");
        let frames: Vec<Vec<[i16; 3]>> = (0..3).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
        let good = write_test_md3(&frames, &[[0, 1, 2]]);
        std::fs::write(&path, &good).unwrap();
        assert_eq!(list_takes(&path).unwrap()[0].frames, 3);
        let (clip, _, _) = read(&path, &ReadOptions::default()).unwrap();
        // Frame 2, vertex 2 = (0, 1, 2) → Y-up (0, 2, −1).
        assert_eq!(clip.frame(2)[2], [0.0, 2.0, -1.0]);
        assert_eq!(clip.faces, vec![[0, 1, 2]]);
        for cut in [3, 100, 150, good.len() - 2] {
            std::fs::write(&path, &good[..cut]).unwrap();
            assert!(read(&path, &ReadOptions::default()).is_err(), "cut {cut}");
        }
        std::fs::write(&path, write_test_md3(&frames[..1], &[[0, 1, 2]])).unwrap();
        assert!(
            read(&path, &ReadOptions::default())
                .unwrap_err()
                .reason
                .contains("static mesh")
        );
    }
}
