//! OBJ sequences (docs/method.md §2.1 clip record): a folder of per-frame `.obj` files sharing one topology.
//!
//! Frames are the folder's `.obj` files in natural order (`f2` before `f10`); faces come from frame 0 and every
//! frame must have the same vertex count and faces. Polygons are triangulated as fans `(0, i, i+1)`; face corners
//! may be written `v`, `v/vt`, `v//vn` or `v/vt/vn`, with negative (relative) indices. The caption is the optional
//! `caption.txt` in the folder (trailing newline dropped); without it the caption is " " as for `.bin` files.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use super::dymesh_bin::MISSING_CAPTION;
use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::io::write_atomic;

/// Name of the caption file inside an OBJ sequence folder.
pub const CAPTION_FILE: &str = "caption.txt";
/// Largest caption file read: 1 MiB (captions are a sentence).
pub const MAX_CAPTION_BYTES: u64 = 1 << 20;

/// Ending of a scene file beside an import source (docs/method.md §6.5): `walk.scene.obj` for `walk.bin`,
/// `walk.glb` or the OBJ folder `walk/`.
pub const SCENE_SUFFIX: &str = ".scene.obj";

/// Whether `path` names a scene file (read with the source it sits beside, never as a clip or an OBJ frame).
pub fn is_scene_file(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.to_string_lossy().to_ascii_lowercase().ends_with(SCENE_SUFFIX))
}

/// Read an OBJ sequence folder. The id is the folder name, the source the folder path.
pub fn read_obj_seq(dir: &Path) -> Result<Clip> {
    let files = frame_files(dir)?;
    if files.is_empty() {
        return Err(DataError::new(dir, "frames", "folder holds no .obj files"));
    }
    let max = crate::limits::FRAMES.get_usize();
    if files.len() > max {
        return Err(DataError::new(
            dir,
            "frames",
            format!(
                "{} .obj frames, more than the limit of {max}{}",
                files.len(),
                crate::limits::FRAMES.hint()
            ),
        ));
    }
    let mut vertices = Vec::new();
    let mut first: Option<(usize, Vec<[u32; 3]>)> = None;
    for file in &files {
        let bytes = super::read_clip_file(file)?;
        let text =
            String::from_utf8(bytes).map_err(|e| DataError::new(file, "file", format!("not UTF-8 text: {e}")))?;
        let (v, f) = parse_obj(&text, file)?;
        match &first {
            None => first = Some((v.len(), f)),
            Some((n, faces)) => {
                if v.len() != *n {
                    return Err(DataError::new(
                        file,
                        "vertices",
                        format!("{} vertices, frame 0 ({}) has {n}", v.len(), files[0].display()),
                    ));
                }
                if let Some(i) = (0..faces.len().max(f.len())).find(|&i| faces.get(i) != f.get(i)) {
                    return Err(DataError::new(
                        file,
                        "faces",
                        format!("triangle {i} is {:?}, frame 0 has {:?}", f.get(i), faces.get(i)),
                    ));
                }
            }
        }
        vertices.extend(v);
    }
    let (n_vertices, faces) = first.expect("at least one file");
    let caption_path = dir.join(CAPTION_FILE);
    let caption = match std::fs::metadata(&caption_path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => MISSING_CAPTION.to_string(),
        _ => {
            let bytes = super::read_file(&caption_path, MAX_CAPTION_BYTES)?;
            let s = String::from_utf8(bytes)
                .map_err(|e| DataError::new(&caption_path, "caption", format!("not UTF-8 text: {e}")))?;
            s.strip_suffix('\n')
                .map(|s| s.strip_suffix('\r').unwrap_or(s))
                .unwrap_or(&s)
                .to_string()
        }
    };
    let id = dir
        .file_name()
        .map_or_else(|| dir.display().to_string(), |s| s.to_string_lossy().into_owned());
    Clip::new(
        id,
        vertices,
        files.len(),
        n_vertices,
        faces,
        caption,
        dir.display().to_string(),
    )
}

/// The `.obj` files of `dir` in natural order. An entry named `*.obj` that is not a regular file (a folder, a
/// FIFO, a link to a device or to nothing) is an error, not a frame silently left out.
fn frame_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| DataError::io(dir, e))?.path();
        // A scene file beside the frames is the clip's scene, not a frame (docs/method.md §6.5).
        if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")) || is_scene_file(&path) {
            continue;
        }
        if !path.is_file() {
            return Err(DataError::new(
                &path,
                "frames",
                "named as an .obj frame but not a regular file (a folder, a FIFO, a device or a dangling link)",
            ));
        }
        files.push(path);
    }
    files.sort_by(|a, b| {
        natural_cmp(
            &a.file_name().unwrap_or_default().to_string_lossy(),
            &b.file_name().unwrap_or_default().to_string_lossy(),
        )
    });
    Ok(files)
}

/// Natural order: digit runs compare as numbers, the rest as text.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    fn runs(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[start].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ra, rb) = (runs(a), runs(b));
    for (x, y) in ra.iter().zip(&rb) {
        let ord = match (x, y) {
            ((true, x), (true, y)) => {
                let (tx, ty) = (x.trim_start_matches('0'), y.trim_start_matches('0'));
                tx.len()
                    .cmp(&ty.len())
                    .then_with(|| tx.cmp(ty))
                    .then_with(|| x.len().cmp(&y.len()))
            }
            ((_, x), (_, y)) => x.cmp(y),
        };
        if ord != Ordering::Equal {
            return ord;
        }
    }
    ra.len().cmp(&rb.len())
}

/// One parsed OBJ file: positions and triangles (0-based).
pub type ObjFrame = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// Parse one OBJ file: positions and fan-triangulated faces (0-based). Errors name the file and the line.
pub fn parse_obj(text: &str, path: &Path) -> Result<ObjFrame> {
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line_err = |reason: String| DataError::new(path, format!("line {}", k + 1), reason);
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut tokens = line.split_whitespace();
        match tokens.next() {
            Some("v") => {
                let xyz: Vec<f32> = tokens
                    .take(3)
                    .map(|t| {
                        t.parse::<f32>()
                            .map_err(|e| line_err(format!("vertex coordinate `{t}`: {e}")))
                    })
                    .collect::<Result<_>>()?;
                let [x, y, z] = xyz[..] else {
                    return Err(line_err(format!("vertex has {} coordinates, expected 3", xyz.len())));
                };
                if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                    return Err(line_err(format!("non-finite vertex ({x}, {y}, {z})")));
                }
                positions.push([x, y, z]);
            }
            Some("f") => {
                let corners = tokens
                    .map(|t| {
                        let first = t.split('/').next().unwrap_or("");
                        let i: i64 = first.parse().map_err(|e| line_err(format!("face corner `{t}`: {e}")))?;
                        let n = positions.len() as i64;
                        // 1-based; negative counts back from the last vertex read so far.
                        let idx = if i > 0 { i - 1 } else { n + i };
                        if i == 0 || idx < 0 || idx >= n {
                            return Err(line_err(format!("face index {i} outside the {n} vertices read so far")));
                        }
                        Ok(idx as u32)
                    })
                    .collect::<Result<Vec<u32>>>()?;
                if corners.len() < 3 {
                    return Err(line_err(format!(
                        "face has {} corners, expected at least 3",
                        corners.len()
                    )));
                }
                faces.extend((1..corners.len() - 1).map(|i| [corners[0], corners[i], corners[i + 1]]));
            }
            _ => {}
        }
    }
    Ok((positions, faces))
}

/// Write `clip` as `dir/frame_0000.obj`, … plus `dir/caption.txt`. Refuses a folder that already holds `.obj`
/// files, so that stale frames never join the sequence.
pub fn write_obj_seq(dir: &Path, clip: &Clip) -> Result<()> {
    clip.validate()?;
    std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    if let Some(old) = frame_files(dir)?.first() {
        return Err(DataError::new(
            dir,
            "frames",
            format!("folder already holds OBJ frames ({})", old.display()),
        ));
    }
    let faces: String = clip
        .faces
        .iter()
        .map(|[a, b, c]| format!("f {} {} {}\n", a + 1, b + 1, c + 1))
        .collect();
    for f in 0..clip.frames {
        let mut text = format!("# any4d clip {} frame {f}\n", clip.id);
        for [x, y, z] in clip.frame(f) {
            text.push_str(&format!("v {x} {y} {z}\n"));
        }
        text.push_str(&faces);
        write_atomic(&dir.join(format!("frame_{f:04}.obj")), text.as_bytes())?;
    }
    write_atomic(&dir.join(CAPTION_FILE), format!("{}\n", clip.caption).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut names = vec!["f10.obj", "f2.obj", "f1.obj", "f02b.obj", "a.obj"];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(names, ["a.obj", "f1.obj", "f2.obj", "f02b.obj", "f10.obj"]);
    }

    #[test]
    fn fans_slashes_and_relative_indices() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 # quad\nvt 0 0\nf 1/1 2//3 3/1/1 -1\n";
        let (v, f) = parse_obj(text, Path::new("q.obj")).unwrap();
        assert_eq!(v.len(), 4);
        assert_eq!(f, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn a_frame_that_is_not_a_regular_file_is_an_error() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("0.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        std::fs::copy(tmp.path().join("0.obj"), tmp.path().join("2.obj")).unwrap();
        assert_eq!(read_obj_seq(tmp.path()).unwrap().frames, 2);
        for (name, make) in [
            ("1.obj", &(|p: &Path| std::fs::create_dir(p).unwrap()) as &dyn Fn(&Path)),
            ("1.obj", &|p: &Path| std::os::unix::fs::symlink("/dev/null", p).unwrap()),
            ("1.obj", &|p: &Path| std::os::unix::fs::symlink("gone", p).unwrap()),
        ] {
            let frame = tmp.path().join(name);
            make(&frame);
            let e = read_obj_seq(tmp.path()).unwrap_err();
            assert!(
                e.reason.contains("not a regular file") && e.path.ends_with("1.obj"),
                "{e}"
            );
            if frame.is_dir() {
                std::fs::remove_dir(&frame).unwrap();
            } else {
                std::fs::remove_file(&frame).unwrap();
            }
        }
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse_obj("v 0 0 0\nv 1 0\n", Path::new("a.obj")).unwrap_err();
        assert_eq!((e.path.as_str(), e.field.as_str()), ("a.obj", "line 2"));
        let e = parse_obj("v 0 0 0\nf 1 2 3\n", Path::new("a.obj")).unwrap_err();
        assert!(e.field == "line 2" && e.reason.contains("index 2"), "{e}");
    }
}
