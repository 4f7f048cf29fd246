//! Quake III `.md3` (version 15): per-frame vertex animation of one or more surfaces, `i16` coordinates / 64.
//!
//! Takes: a Quake III player's body part (`lower*.md3`, `upper*.md3`) with an `animation.cfg` beside it has the
//! takes that file lists for it ([`cfg_takes`]); any other `.md3` has one take, `all`, holding every frame. All
//! surfaces go into one vertex list; every surface must have the file's frame count. Coordinates go from Z-up to
//! Y-up ([`super::skeletal::z_up_to_y_up`]).
//!
//! Layout (little-endian): 108-byte header (`IDP3`, version, name [64], flags, frame / tag / surface / skin
//! counts, offsets of frames, tags, surfaces, end); each surface: `IDP3`, name [64], flags, frame, shader,
//! vertex and triangle counts, then offsets (from the surface start) of triangles (`i32 × 3`), shaders,
//! texture coordinates, vertices (`i16 x, y, z, u16 normal` per vertex per frame) and the surface's end.

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{self, ReadOptions, SkinStats, TakeInfo, z_up_to_y_up};
use crate::clip::Clip;
use crate::error::{DataError, Result};

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

/// Names of the animations of a Quake III player's `animation.cfg`, in the order of its numeric lines (Quake III
/// Arena's 25, then Team Arena's 6).
pub const ANIMATIONS: [&str; 31] = [
    "BOTH_DEATH1",
    "BOTH_DEAD1",
    "BOTH_DEATH2",
    "BOTH_DEAD2",
    "BOTH_DEATH3",
    "BOTH_DEAD3",
    "TORSO_GESTURE",
    "TORSO_ATTACK",
    "TORSO_ATTACK2",
    "TORSO_DROP",
    "TORSO_RAISE",
    "TORSO_STAND",
    "TORSO_STAND2",
    "LEGS_WALKCR",
    "LEGS_WALK",
    "LEGS_RUN",
    "LEGS_BACK",
    "LEGS_SWIM",
    "LEGS_JUMP",
    "LEGS_LAND",
    "LEGS_JUMPB",
    "LEGS_LANDB",
    "LEGS_IDLE",
    "LEGS_IDLECR",
    "LEGS_TURN",
    "TORSO_GETFLAG",
    "TORSO_GUARDBASE",
    "TORSO_PATROL",
    "TORSO_FOLLOWME",
    "TORSO_AFFIRMATIVE",
    "TORSO_NEGATIVE",
];

/// Largest `animation.cfg` read, in bytes.
pub const MAX_CFG_BYTES: u64 = 1 << 20;

/// A take of an `.md3`: what `data inspect` lists, where its frames start and whether they play backwards.
struct Range {
    info: TakeInfo,
    first: usize,
    reverse: bool,
}

/// The takes an `animation.cfg` gives body part `part` (`lower` or `upper`) of a player whose `.md3` has
/// `frames` frames. Each numeric line is `first frame, frame count, looping frames, frames per second` of the next
/// animation of [`ANIMATIONS`] (a negative count plays backwards); lines starting with a word (`sex`,
/// `footsteps`, …) and `//` comments are skipped. `BOTH_*` animations belong to both parts, `TORSO_*` to the
/// upper and `LEGS_*` to the lower body, whose file numbers its frames without the torso's: as Quake III does,
/// the `LEGS_*` first frames are moved down by `LEGS_WALKCR`'s first frame minus `TORSO_GESTURE`'s. Animations of
/// fewer than 2 frames are not takes; one that runs past the file's frames is an error naming it.
pub fn cfg_takes(cfg: &Path, text: &str, part: &str, frames: usize) -> Result<Vec<TakeInfo>> {
    Ok(cfg_ranges(cfg, text, part, frames)?
        .into_iter()
        .map(|r| r.info)
        .collect())
}

fn cfg_ranges(cfg: &Path, text: &str, part: &str, frames: usize) -> Result<Vec<Range>> {
    let mut rows: Vec<(i64, i64, f32)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split("//").next().unwrap_or_default();
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let Some(first) = tokens.first() else { continue };
        if !first.starts_with(|c: char| c.is_ascii_digit() || c == '-') {
            continue;
        }
        let err = |what: &str| DataError::new(cfg, format!("line {}", n + 1), what.to_owned());
        if tokens.len() < 4 {
            return Err(err(
                "an animation line needs first frame, frame count, looping frames and fps",
            ));
        }
        let int = |t: &str| {
            t.parse::<i64>()
                .map_err(|_| err(&format!("{t:?} is not a whole number")))
        };
        let fps: f32 = tokens[3]
            .parse()
            .map_err(|_| err(&format!("{:?} is not a frame rate", tokens[3])))?;
        let (start, count, _looping) = (int(tokens[0])?, int(tokens[1])?, int(tokens[2])?);
        if start < 0 || !(fps.is_finite() && fps >= 0.0) {
            return Err(err(&format!("first frame {start} at {fps} fps")));
        }
        // Quake III plays an animation listed at 0 fps at 1 fps (real players list unused ones as `0 0 0 0`).
        let fps = if fps == 0.0 { 1.0 } else { fps };
        if rows.len() == ANIMATIONS.len() {
            return Err(err(&format!(
                "more than the {} animations a player has",
                ANIMATIONS.len()
            )));
        }
        rows.push((start, count, fps));
    }
    let index = |name: &str| ANIMATIONS.iter().position(|a| *a == name).expect("a known animation");
    let skip = match (rows.get(index("LEGS_WALKCR")), rows.get(index("TORSO_GESTURE"))) {
        (Some(legs), Some(torso)) => legs.0 - torso.0,
        _ => 0,
    };
    let mut out = Vec::new();
    for (name, &(start, count, fps)) in ANIMATIONS.iter().zip(&rows) {
        let legs = name.starts_with("LEGS_");
        let mine = name.starts_with("BOTH_") || (part == "lower") == legs;
        let len = count.unsigned_abs() as usize;
        if !mine || len < 2 {
            continue;
        }
        let first = if legs {
            i128::from(start) - i128::from(skip)
        } else {
            i128::from(start)
        };
        let end = usize::try_from(first).ok().and_then(|f| f.checked_add(len));
        let Some(end) = end.filter(|&e| e <= frames) else {
            return Err(DataError::new(
                cfg,
                *name,
                format!(
                    "frames {first}..{} for the {part} body, but its .md3 has {frames}",
                    first + len as i128
                ),
            ));
        };
        out.push(Range {
            info: TakeInfo {
                name: (*name).to_owned(),
                frames: len,
                fps,
                file: Some(cfg.to_path_buf()),
            },
            first: end - len,
            reverse: count < 0,
        });
    }
    Ok(out)
}

/// The `animation.cfg` beside a player's `lower*.md3` or `upper*.md3`, and which part the file is.
fn player_cfg(path: &Path) -> Option<(std::path::PathBuf, &'static str)> {
    let stem = path.file_stem()?.to_string_lossy().to_ascii_lowercase();
    let part = ["lower", "upper"].into_iter().find(|p| stem.starts_with(p))?;
    let dir = path.parent()?;
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let cfg = std::fs::read_dir(dir).ok()?.flatten().map(|e| e.path()).find(|p| {
        p.file_name().is_some_and(|n| n.eq_ignore_ascii_case("animation.cfg")) && skeletal::sidecar_inside(dir, p)
    })?;
    Some((cfg, part))
}

/// The takes of an `.md3` with `frames` frames: from the player's `animation.cfg`, else `all`.
fn ranges(path: &Path, frames: usize) -> Result<Vec<Range>> {
    let Some((cfg, part)) = player_cfg(path) else {
        return Ok(skeletal::single_take(frames)
            .into_iter()
            .map(|info| Range {
                info,
                first: 0,
                reverse: false,
            })
            .collect());
    };
    let text = String::from_utf8_lossy(&super::read_file(&cfg, MAX_CFG_BYTES)?).into_owned();
    cfg_ranges(&cfg, &text, part, frames)
}

/// The takes of an `.md3`: the player's animations from its `animation.cfg`, else `all` when it has at least 2
/// frames.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    let frames = parse(&mut Bytes::new(&s, &data))?.frames;
    Ok(ranges(path, frames)?.into_iter().map(|r| r.info).collect())
}

/// Read the frames of an `.md3` as a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let data = super::read_clip_file(path)?;
    let s = path.display().to_string();
    let mut b = Bytes::new(&s, &data);
    let m = parse(&mut b)?;
    let takes = ranges(path, m.frames)?;
    let infos: Vec<TakeInfo> = takes.iter().map(|r| r.info.clone()).collect();
    let take = &takes[skeletal::pick(path, &infos, &opts.take)?];
    let info = take.info.clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    let n: usize = m.surfaces.iter().map(|s| s.verts).sum();
    let mut faces = Vec::new();
    let mut base = 0u32;
    for s in &m.surfaces {
        faces.extend(s.faces.iter().map(|f| f.map(|i| i + base)));
        base += s.verts as u32;
    }
    skeletal::check_rows(path, info.frames, n)?;
    let mut vertices = Vec::with_capacity(info.frames * n);
    for k in 0..info.frames {
        let f = take.first + if take.reverse { info.frames - 1 - k } else { k };
        for (k, s) in m.surfaces.iter().enumerate() {
            b.seek(s.ofs_xyz + f * s.verts * 8, &format!("surfaces[{k}].xyz"))?;
            for _ in 0..s.verts {
                let p = [b.i16("xyz")?, b.i16("xyz")?, b.i16("xyz")?].map(|c| c as f64 / 64.0);
                b.u16("normal")?;
                vertices.push(z_up_to_y_up(p).map(|x| x as f32));
            }
        }
    }
    let clip = Clip::new(skeletal::stem(path), vertices, info.frames, n, faces, "", s.clone())?;
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

    /// An `animation.cfg` laid out as Quake III's: the six `BOTH_*` lines (three 1-frame `DEAD` poses), seven
    /// 2-frame `TORSO_*` lines from frame 8, then `LEGS_WALKCR` and a backwards `LEGS_WALK` numbered after the
    /// torso's frames (22, 24: frames 8 and 10 of `lower.md3`).
    const CFG: &str = "// animation config file\nsex m\nfootsteps normal\n\
        0 3 0 20 // BOTH_DEATH1\n2 1 0 20\n3 3 0 20\n5 1 0 20\n6 2 0 20\n7 1 0 20\n\
        8 2 0 15\n10 2 0 15\n12 2 0 15\n14 2 0 15\n16 2 0 15\n18 2 0 15\n20 2 0 15\n\
        22 2 2 25\n24 -2 2 25 // LEGS_WALK, backwards\n";

    /// An `.md3` of `n` frames whose vertex 2 sits at height = frame index (after the turn to Y-up).
    fn frames_md3(n: i16) -> Vec<u8> {
        let frames: Vec<Vec<[i16; 3]>> = (0..n).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
        write_test_md3(&frames, &[[0, 1, 2]])
    }

    #[test]
    fn player_takes_come_from_animation_cfg() {
        let dir = tempfile::tempdir().unwrap();
        let (lower, upper, other) = (
            dir.path().join("lower.md3"),
            dir.path().join("upper_1.md3"),
            dir.path().join("flag.md3"),
        );
        std::fs::write(&lower, frames_md3(12)).unwrap();
        std::fs::write(&upper, frames_md3(22)).unwrap();
        std::fs::write(&other, frames_md3(5)).unwrap();
        std::fs::write(dir.path().join("Animation.CFG"), CFG).unwrap();
        let names = |p: &Path| list_takes(p).unwrap().into_iter().map(|t| t.name).collect::<Vec<_>>();
        assert_eq!(
            names(&lower),
            ["BOTH_DEATH1", "BOTH_DEATH2", "BOTH_DEATH3", "LEGS_WALKCR", "LEGS_WALK"]
        );
        let upper_takes = names(&upper);
        assert_eq!(upper_takes.len(), 10);
        assert_eq!(upper_takes[3..5], ["TORSO_GESTURE", "TORSO_ATTACK"]);
        assert_eq!(names(&other), ["all"]);
        let opts = |take: &str| ReadOptions {
            take: skeletal::TakeSel::parse(take),
            ..ReadOptions::default()
        };
        let (clip, _, info) = read(&lower, &opts("LEGS_WALK")).unwrap();
        assert_eq!((info.frames, info.fps), (2, 25.0));
        // Frames 10 and 11 of lower.md3, played backwards.
        assert_eq!([clip.frame(0)[2][1], clip.frame(1)[2][1]], [11.0, 10.0]);
        let (clip, _, _) = read(&upper, &opts("TORSO_STAND2")).unwrap();
        assert_eq!([clip.frame(0)[2][1], clip.frame(1)[2][1]], [20.0, 21.0]);
        // A cfg that runs past the file, and a broken line.
        std::fs::write(&lower, frames_md3(11)).unwrap();
        let e = list_takes(&lower).unwrap_err();
        assert!(e.field == "LEGS_WALK" && e.reason.contains("has 11"), "{e}");
        std::fs::write(dir.path().join("Animation.CFG"), "0 3 x 20\n").unwrap();
        let e = list_takes(&upper).unwrap_err();
        assert!(e.field == "line 1" && e.reason.contains("\"x\""), "{e}");
    }

    #[test]
    fn an_animation_at_0_fps_plays_at_1_and_huge_first_frames_are_refused_without_overflow() {
        let dir = tempfile::tempdir().unwrap();
        let lower = dir.path().join("lower.md3");
        std::fs::write(&lower, frames_md3(12)).unwrap();
        // A real player's unused LEGS_TURN line: `192 0 0 0`; and a 2-frame LEGS_WALKCR listed at 0 fps.
        let cfg = CFG.replace("22 2 2 25\n", "22 2 2 0\n") + "192 0 0 0 // LEGS_TURN\n";
        std::fs::write(dir.path().join("animation.cfg"), cfg).unwrap();
        let takes = list_takes(&lower).unwrap();
        let walkcr = takes.iter().find(|t| t.name == "LEGS_WALKCR").unwrap();
        assert_eq!((walkcr.frames, walkcr.fps), (2, 1.0));
        for (line, needle) in [
            (format!("{} 2 0 20\n", i64::MAX), "frames"),
            ("0 2 0 -5\n".to_string(), "-5 fps"),
            ("0 2 0 NaN\n".to_string(), "NaN fps"),
            ("0 2 0 inf\n".to_string(), "inf fps"),
        ] {
            // BOTH_DEATH1 gets the hostile line; the legs' skip is computed from rows that are all present.
            let cfg = CFG.replacen("0 3 0 20 // BOTH_DEATH1\n", &line, 1);
            std::fs::write(dir.path().join("animation.cfg"), &cfg).unwrap();
            let e = list_takes(&lower).unwrap_err();
            assert!(e.to_string().contains(needle), "{line:?}: {e}");
        }
        // A legs line whose first frame lies below the torso's skip: refused, not wrapped around.
        let cfg = CFG.replace("24 -2 2 25", "5 -2 2 25");
        std::fs::write(dir.path().join("animation.cfg"), cfg).unwrap();
        let e = list_takes(&lower).unwrap_err();
        assert!(e.field == "LEGS_WALK" && e.reason.contains("frames -9..-7"), "{e}");
    }
}
