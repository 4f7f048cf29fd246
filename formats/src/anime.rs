//! DeformingThings4D `.anime`: a vertex animation as a frame-0 mesh plus per-frame offsets.
//!
//! Layout (little-endian): `n_frames i32 | n_vertices i32 | n_faces i32 | frame-0 vertices f32 × n_vertices × 3 |
//! faces i32 × n_faces × 3 | offsets f32 × (n_frames − 1) × n_vertices × 3`, where frame `f ≥ 1` is frame 0
//! plus offsets block `f − 1`. One take, `all`; coordinates are kept.

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo};
use crate::clip::Clip;
use crate::error::Result;

struct Head {
    frames: usize,
    verts: usize,
    faces: usize,
}

fn head(b: &mut Bytes) -> Result<Head> {
    let frames = b.count_i32("n_frames")?;
    let verts = b.count_i32("n_vertices")?;
    let faces = b.count_i32("n_faces")?;
    // Check the whole claimed size against the file before allocating anything.
    let need = frames
        .checked_mul(verts)
        .and_then(|x| x.checked_mul(12))
        .and_then(|x| x.checked_add(faces.checked_mul(12)?));
    match need {
        Some(n) if n + 12 == b.len() => Ok(Head { frames, verts, faces }),
        _ => Err(b.err(
            "n_frames",
            format!(
                "{frames} frames × {verts} vertices and {faces} faces do not match the file's {} bytes",
                b.len()
            ),
        )),
    }
}

/// The takes of an `.anime`: `all` when it has at least 2 frames.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    Ok(skeletal::single_take(head(&mut Bytes::new(&s, &data))?.frames))
}

/// Read an `.anime` as a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    let mut b = Bytes::new(&s, &data);
    let h = head(&mut b)?;
    let info = skeletal::pick_single(path, h.frames, opts)?;
    let base = (0..h.verts)
        .map(|_| b.f32s::<3>("vertices"))
        .collect::<Result<Vec<_>>>()?;
    let mut faces = Vec::with_capacity(h.faces);
    for k in 0..h.faces {
        let f = format!("faces[{k}]");
        let tri = [b.i32(&f)?, b.i32(&f)?, b.i32(&f)?];
        let ok = tri.iter().all(|&i| i >= 0 && (i as usize) < h.verts);
        if !ok {
            return Err(b.err(f, format!("{tri:?} indexes outside the {} vertices", h.verts)));
        }
        faces.push(tri.map(|i| i as u32));
    }
    let mut vertices = Vec::with_capacity(h.frames * h.verts);
    vertices.extend(&base);
    for f in 1..h.frames {
        for p in &base {
            let d = b.f32s::<3>(&format!("offsets[{}]", f - 1))?;
            vertices.push([p[0] + d[0], p[1] + d[1], p[2] + d[2]]);
        }
    }
    let clip = Clip::new(skeletal::stem(path), vertices, h.frames, h.verts, faces, "", s.clone())?;
    Ok((clip, SkinStats::default(), info))
}

/// Bytes of an `.anime` holding `clip`'s frames and faces.
pub fn write_anime(clip: &Clip) -> Vec<u8> {
    let mut out = Vec::new();
    for x in [clip.frames, clip.n_vertices, clip.faces.len()] {
        out.extend((x as i32).to_le_bytes());
    }
    clip.frame(0).iter().flatten().for_each(|x| out.extend(x.to_le_bytes()));
    clip.faces
        .iter()
        .flatten()
        .for_each(|&i| out.extend((i as i32).to_le_bytes()));
    for f in 1..clip.frames {
        for (p, q) in clip.frame(f).iter().zip(clip.frame(0)) {
            (0..3).for_each(|c| out.extend((p[c] - q[c]).to_le_bytes()));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_checks_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("deer.anime");
        let v = (0..3)
            .flat_map(|f| [[0.0, 0.0, f as f32], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5 * f as f32]])
            .collect();
        let clip = Clip::new("deer", v, 3, 3, vec![[0, 1, 2]], "", "mem").unwrap();
        let bytes = write_anime(&clip);
        std::fs::write(&path, &bytes).unwrap();
        let (back, _, info) = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!((back.vertices, back.faces, info.frames), (clip.vertices, clip.faces, 3));
        // A frame count the bytes cannot hold is refused before allocation.
        let mut bad = bytes.clone();
        bad[..4].copy_from_slice(&i32::MAX.to_le_bytes());
        std::fs::write(&path, &bad).unwrap();
        assert!(
            read(&path, &ReadOptions::default())
                .unwrap_err()
                .reason
                .contains("do not match")
        );
        let mut bad = bytes;
        bad[12 + 36..16 + 36].copy_from_slice(&9i32.to_le_bytes());
        std::fs::write(&path, &bad).unwrap();
        assert_eq!(read(&path, &ReadOptions::default()).unwrap_err().field, "faces[0]");
    }
}
