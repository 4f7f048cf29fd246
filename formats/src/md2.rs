//! Quake II `.md2` (version 8): per-frame vertex animation, quantised to bytes with a per-frame scale and offset.
//!
//! Takes: when an `.anm` file with the model's stem sits beside it (UFO: Alien Invasion's `name start end fps`
//! lines, inclusive frame ranges), its ranges of at least 2 frames, each range once (the first name wins);
//! otherwise runs of consecutive frames whose names share a prefix after stripping trailing digits (Quake's
//! `stand01`…`stand40` → `stand`). Coordinates go from Z-up to Y-up ([`super::skeletal::z_up_to_y_up`]).
//!
//! Layout (little-endian): 68-byte header (`IDP2`, version, skin size, frame size, counts of skins, vertices,
//! texture coordinates, triangles, GL commands, frames, then offsets), triangles of `u16 × 3` vertex + `u16 × 3`
//! texture indices, frames of `scale f32×3, translate f32×3, name [16], (u8 x, y, z, normal) × vertices`.

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo, z_up_to_y_up};
use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Largest `.anm` file read, in bytes.
const MAX_ANM_BYTES: u64 = 1 << 20;

struct Md2<'a> {
    b: Bytes<'a>,
    num_vertices: usize,
    num_frames: usize,
    frame_size: usize,
    ofs_frames: usize,
    faces: Vec<[u32; 3]>,
}

fn parse<'a>(path: &'a str, data: &'a [u8]) -> Result<Md2<'a>> {
    let mut b = Bytes::new(path, data);
    if b.take(4, "ident").ok() != Some(&b"IDP2"[..]) {
        return Err(b.err("ident", "not an MD2 file (no IDP2 header)"));
    }
    let version = b.i32("version")?;
    if version != 8 {
        return Err(b.err("version", format!("version {version}, only 8 is supported")));
    }
    let _skin_w = b.i32("skinwidth")?;
    let _skin_h = b.i32("skinheight")?;
    let frame_size = b.count_i32("framesize")?;
    let _num_skins = b.count_i32("num_skins")?;
    let num_vertices = b.count_i32("num_xyz")?;
    let _num_st = b.count_i32("num_st")?;
    let num_tris = b.count_i32("num_tris")?;
    let _num_glcmds = b.count_i32("num_glcmds")?;
    let num_frames = b.count_i32("num_frames")?;
    let _ofs_skins = b.count_i32("ofs_skins")?;
    let _ofs_st = b.count_i32("ofs_st")?;
    let ofs_tris = b.count_i32("ofs_tris")?;
    let ofs_frames = b.count_i32("ofs_frames")?;
    if frame_size != 40 + 4 * num_vertices {
        return Err(b.err(
            "framesize",
            format!(
                "{frame_size} bytes, but {num_vertices} vertices need {}",
                40 + 4 * num_vertices
            ),
        ));
    }
    b.check_count_at(ofs_frames, num_frames, frame_size, "frames")?;
    b.check_count_at(ofs_tris, num_tris, 12, "triangles")?;
    b.seek(ofs_tris, "ofs_tris")?;
    let mut faces = Vec::with_capacity(num_tris);
    for t in 0..num_tris {
        let f = format!("triangles[{t}]");
        let tri = [b.u16(&f)?, b.u16(&f)?, b.u16(&f)?].map(u32::from);
        b.take(6, &f)?;
        if let Some(&i) = tri.iter().find(|&&i| i as usize >= num_vertices) {
            return Err(b.err(f, format!("vertex {i} of {num_vertices}")));
        }
        // Quake winds clockwise; the clip convention is counter-clockwise.
        faces.push([tri[0], tri[2], tri[1]]);
    }
    Ok(Md2 {
        b,
        num_vertices,
        num_frames,
        frame_size,
        ofs_frames,
        faces,
    })
}

fn frame_name(m: &mut Md2, f: usize) -> Result<String> {
    m.b.seek(m.ofs_frames + f * m.frame_size + 24, "frames")?;
    m.b.name(16, &format!("frames[{f}].name"))
}

/// `(name, first, count, fps)` per animation, one-frame poses included.
fn all_ranges(path: &Path, m: &mut Md2) -> Result<Vec<(String, usize, usize, f32)>> {
    let anm = path.with_extension("anm");
    if anm.is_file() {
        if !skeletal::sidecar_inside(path.parent().unwrap_or(Path::new(".")), &anm) {
            return Err(DataError::new(
                &anm,
                "file",
                "the animation table leads out of the model's folder (a link elsewhere); sidecars are read only \
                 from inside it",
            ));
        }
        let len = std::fs::metadata(&anm).map_err(|e| DataError::io(&anm, e))?.len();
        if len > MAX_ANM_BYTES {
            return Err(DataError::new(
                &anm,
                "file",
                format!("{len} bytes, more than {MAX_ANM_BYTES}"),
            ));
        }
        let text = std::fs::read_to_string(&anm).map_err(|e| DataError::io(&anm, e))?;
        let mut out: Vec<(String, usize, usize, f32)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split("//").next().unwrap_or("");
            let parts: Vec<&str> = line.split_whitespace().collect();
            if parts.is_empty() {
                continue;
            }
            let bad = || {
                DataError::new(
                    &anm,
                    format!("line {}", i + 1),
                    format!("expected `name start end fps`: {line:?}"),
                )
            };
            let [name, s, e, fps] = parts[..] else {
                return Err(bad());
            };
            let (s, e): (usize, usize) = (s.parse().map_err(|_| bad())?, e.parse().map_err(|_| bad())?);
            let fps: f64 = fps.parse().map_err(|_| bad())?;
            let fps = skeletal::check_fps(&anm, &format!("line {}", i + 1), fps)?;
            if e >= m.num_frames || s > e {
                return Err(DataError::new(
                    &anm,
                    format!("line {}", i + 1),
                    format!("frames {s}..={e} outside the model's {} frames", m.num_frames),
                ));
            }
            if !out.iter().any(|r| r.1 == s && r.2 == e - s + 1) {
                out.push((name.to_owned(), s, e - s + 1, fps));
            }
        }
        return Ok(out);
    }
    let mut out: Vec<(String, usize, usize, f32)> = Vec::new();
    for f in 0..m.num_frames {
        let name = frame_name(m, f)?;
        let prefix = name.trim_end_matches(|c: char| c.is_ascii_digit()).to_owned();
        match out.last_mut() {
            Some(last) if last.0 == prefix && last.1 + last.2 == f => last.2 += 1,
            _ => out.push((prefix, f, 1, 10.0)),
        }
    }
    Ok(out)
}

/// The takes' ranges: those of [`all_ranges`] with at least 2 frames.
fn ranges(path: &Path, m: &mut Md2) -> Result<Vec<(String, usize, usize, f32)>> {
    let mut r = all_ranges(path, m)?;
    r.retain(|r| r.2 >= 2);
    Ok(r)
}

fn infos(r: &[(String, usize, usize, f32)]) -> Vec<TakeInfo> {
    r.iter()
        .map(|(name, _, count, fps)| TakeInfo {
            name: name.clone(),
            frames: *count,
            fps: *fps,
            file: None,
        })
        .collect()
}

fn load(path: &Path) -> Result<Vec<u8>> {
    super::read_clip_file(path)
}

/// The takes of an `.md2` (see the module doc).
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let data = load(path)?;
    let s = path.display().to_string();
    let mut m = parse(&s, &data)?;
    Ok(infos(&ranges(path, &mut m)?))
}

/// The animations of an `.md2` that have one frame (poses, not takes), by name.
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    let data = load(path)?;
    let s = path.display().to_string();
    let mut m = parse(&s, &data)?;
    Ok(all_ranges(path, &mut m)?
        .into_iter()
        .filter(|r| r.2 < 2)
        .map(|r| r.0)
        .collect())
}

/// Read one take of an `.md2` as a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let data = load(path)?;
    let s = path.display().to_string();
    let mut m = parse(&s, &data)?;
    let r = ranges(path, &mut m)?;
    let takes = infos(&r);
    let k = skeletal::pick(path, &takes, &opts.take)?;
    let (_, first, count, _) = r[k];
    skeletal::check_frames(path, &takes[k].name, count, opts.max_frames)?;
    let n = m.num_vertices;
    let mut vertices = Vec::with_capacity(count * n);
    for f in first..first + count {
        let field = format!("frames[{f}]");
        m.b.seek(m.ofs_frames + f * m.frame_size, &field)?;
        let scale = m.b.f32s::<3>(&field)?;
        let translate = m.b.f32s::<3>(&field)?;
        m.b.take(16, &field)?;
        for _ in 0..n {
            let q = m.b.take(4, &field)?;
            let p: [f64; 3] = std::array::from_fn(|c| (q[c] as f32 * scale[c] + translate[c]) as f64);
            vertices.push(z_up_to_y_up(p).map(|x| x as f32));
        }
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        count,
        n,
        m.faces,
        "",
        path.display().to_string(),
    )?;
    Ok((clip, SkinStats::default(), takes[k].clone()))
}

/// Bytes of an MD2 for tests and fixtures: `frames[f]` = (name, vertex positions, each coordinate in 0..=255 after
/// scale 1 and offset 0).
pub fn write_md2(frames: &[(&str, Vec<[u8; 3]>)], faces: &[[u16; 3]]) -> Vec<u8> {
    let n = frames.first().map_or(0, |f| f.1.len());
    let frame_size = 40 + 4 * n;
    let ofs_tris = 68;
    let ofs_frames = ofs_tris + 12 * faces.len();
    let end = ofs_frames + frame_size * frames.len();
    let mut out = b"IDP2".to_vec();
    let header = [
        8,
        256,
        256,
        frame_size,
        0,
        n,
        0,
        faces.len(),
        0,
        frames.len(),
        68,
        68,
        ofs_tris,
        ofs_frames,
        end,
        end,
    ];
    header.iter().for_each(|&x| out.extend((x as i32).to_le_bytes()));
    for t in faces {
        // stored clockwise
        [t[0], t[2], t[1], 0, 0, 0]
            .iter()
            .for_each(|i| out.extend(i.to_le_bytes()));
    }
    for (name, verts) in frames {
        [1.0f32, 1.0, 1.0, 0.0, 0.0, 0.0]
            .iter()
            .for_each(|x| out.extend(x.to_le_bytes()));
        let mut nm = [0u8; 16];
        nm[..name.len().min(15)].copy_from_slice(&name.as_bytes()[..name.len().min(15)]);
        out.extend(nm);
        verts.iter().for_each(|v| out.extend([v[0], v[1], v[2], 0]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<(&'static str, Vec<[u8; 3]>)> {
        let tri = |k: u8| vec![[k, 0, 0], [10 + k, 0, 0], [k, 10, 5]];
        vec![
            ("stand01", tri(0)),
            ("stand02", tri(1)),
            ("run1", tri(2)),
            ("run2", tri(3)),
            ("run3", tri(4)),
            ("pain1", tri(5)),
        ]
    }

    #[test]
    fn takes_from_frame_names_and_from_anm() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("guy.md2");
        std::fs::write(&path, write_md2(&frames(), &[[0, 1, 2]])).unwrap();
        let t = list_takes(&path).unwrap();
        let names: Vec<(&str, usize)> = t.iter().map(|t| (t.name.as_str(), t.frames)).collect();
        assert_eq!(names, [("stand", 2), ("run", 3)]);
        let (clip, _, _) = read(
            &path,
            &ReadOptions {
                take: skeletal::TakeSel::parse("run"),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(clip.frames, 3);
        // Frame 2 (run3) vertex 2 = (4, 10, 5) → Y-up (4, 5, −10).
        assert_eq!(clip.frame(2)[2], [4.0, 5.0, -10.0]);
        assert_eq!(clip.faces, vec![[0, 1, 2]]);
        std::fs::write(
            dir.path().join("guy.anm"),
            "// c\nwalk0 1 4 24\nwalk1 1 4 24\nidle 0 0 1\n",
        )
        .unwrap();
        let t = list_takes(&path).unwrap();
        assert_eq!(t.len(), 1);
        assert_eq!((t[0].name.as_str(), t[0].frames, t[0].fps), ("walk0", 4, 24.0));
        std::fs::write(dir.path().join("guy.anm"), "walk 1 40 24\n").unwrap();
        assert!(list_takes(&path).unwrap_err().reason.contains("outside"));
        // A table reached through a link that leads out of the folder is never read (the sidecar rule).
        let elsewhere = tempfile::tempdir().unwrap();
        std::fs::write(elsewhere.path().join("t.anm"), "walk0 1 4 24\n").unwrap();
        std::fs::remove_file(dir.path().join("guy.anm")).unwrap();
        std::os::unix::fs::symlink(elsewhere.path().join("t.anm"), dir.path().join("guy.anm")).unwrap();
        assert!(
            list_takes(&path)
                .unwrap_err()
                .reason
                .contains("leads out of the model's folder")
        );
        std::fs::remove_file(dir.path().join("guy.anm")).unwrap();
        for rate in ["nan", "inf", "-3", "1e9"] {
            std::fs::write(dir.path().join("guy.anm"), format!("walk0 1 4 {rate}\n")).unwrap();
            let e = list_takes(&path).unwrap_err();
            assert!(e.field == "line 1" && e.reason.contains("frame rate"), "{rate}: {e}");
        }
    }

    #[test]
    fn refuses_truncated_and_inconsistent_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.md2");
        let good = write_md2(&frames(), &[[0, 1, 2]]);
        for cut in [2, 60, 90, good.len() - 1] {
            std::fs::write(&path, &good[..cut]).unwrap();
            assert!(list_takes(&path).is_err(), "cut {cut}");
        }
        let mut bad = good.clone();
        bad[40..44].copy_from_slice(&100_000i32.to_le_bytes()); // num_frames
        std::fs::write(&path, &bad).unwrap();
        assert_eq!(list_takes(&path).unwrap_err().field, "frames");
        let single = write_md2(&frames()[..1], &[[0, 1, 2]]);
        std::fs::write(&path, single).unwrap();
        assert!(
            read(&path, &ReadOptions::default())
                .unwrap_err()
                .reason
                .contains("static mesh")
        );
    }
}
