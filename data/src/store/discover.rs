//! Finding the import jobs under the sources a user names: files of the known formats and folders of `.obj` frames,
//! searched recursively, each visited once by its canonical path, store folders skipped.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};
use crate::formats::{self, Format};

use super::CLIPS_FILE;
use super::jobs::Job;
use super::provenance::{PROVENANCE_FILE, provenance_of};

/// Find import jobs under `sources`, sorted and deduplicated by canonical path; skips the output folder and any
/// folder that holds a store. Also counts, by extension, the files of the searched folders that are not sources
/// (an OBJ folder's frames aside) and a glTF's buffer files.
pub(super) fn discover(sources: &[PathBuf], out: &Path) -> Result<(Vec<Job>, BTreeMap<String, usize>)> {
    let out_canon = std::fs::canonicalize(out).map_err(|e| DataError::io(out, e))?;
    let mut found: Vec<(PathBuf, Result<Format>)> = Vec::new();
    let mut seen = HashSet::new();
    let mut skipped = BTreeMap::new();
    for src in sources {
        match std::fs::canonicalize(src) {
            Err(e) => found.push((src.clone(), Err(DataError::io(src, e)))),
            Ok(path) if path.is_dir() => {
                if super::is_store(&path) {
                    found.push((
                        path,
                        Err(DataError::new(
                            src,
                            CLIPS_FILE,
                            "this folder is an any4d store, not a source",
                        )),
                    ));
                } else {
                    walk(&path, &out_canon, &mut found, &mut seen, &mut skipped);
                }
            }
            Ok(path) => {
                if seen.insert(path.clone()) {
                    let format = Format::from_path(&path);
                    found.push((path, format));
                }
            }
        }
    }
    found.sort_by(|a, b| a.0.cmp(&b.0));
    found.dedup_by(|a, b| a.0 == b.0);
    // A glTF's external buffers are parts of it, not clips of their own.
    let buffers: HashSet<PathBuf> = found
        .iter()
        .filter(|(p, f)| matches!(f, Ok(Format::Gltf)) && p.is_file())
        .flat_map(|(p, _)| formats::gltf::buffer_files(p))
        .filter_map(|b| std::fs::canonicalize(b).ok())
        .collect();
    if !buffers.is_empty() {
        found.retain(|(p, _)| {
            let keep = std::fs::canonicalize(p).map_or(true, |c| !buffers.contains(&c));
            if !keep {
                *skipped.entry(extension(p)).or_insert(0) += 1;
            }
            keep
        });
    }
    let mut cache = HashMap::new();
    let jobs = found
        .into_iter()
        .map(|(path, format)| Job::File {
            source: path.display().to_string(),
            provenance: provenance_of(&path, &mut cache),
            path,
            format,
        })
        .collect();
    Ok((jobs, skipped))
}

/// A path's lower-case extension, `""` when it has none.
fn extension(p: &Path) -> String {
    p.extension()
        .map_or_else(String::new, |e| e.to_string_lossy().to_ascii_lowercase())
}

/// Recursively collect clip files and OBJ-sequence folders under `dir`. Unreadable folders become rejected jobs.
/// Every folder and file is visited once by its canonical path (`seen`), so a symlink cycle ends and a file
/// reached through two links is imported once, under the first path met. Files that are not sources (an OBJ
/// folder's `.obj` frames and the store's own files aside) are counted by extension in `skipped`.
fn walk(
    dir: &Path,
    out: &Path,
    found: &mut Vec<(PathBuf, Result<Format>)>,
    seen: &mut HashSet<PathBuf>,
    skipped: &mut BTreeMap<String, usize>,
) {
    if dir == out || super::is_store(dir) {
        return;
    }
    match std::fs::canonicalize(dir) {
        Ok(canon) => {
            if !seen.insert(canon) {
                return;
            }
        }
        Err(e) => {
            found.push((dir.to_path_buf(), Err(DataError::io(dir, e))));
            return;
        }
    }
    let mut entries: Vec<PathBuf> =
        match std::fs::read_dir(dir).and_then(|rd| rd.map(|e| e.map(|e| e.path())).collect()) {
            Ok(v) => v,
            Err(e) => {
                found.push((dir.to_path_buf(), Err(DataError::io(dir, e))));
                return;
            }
        };
    entries.sort();
    if entries
        .iter()
        .any(|p| p.is_file() && extension(p) == "obj" && !formats::obj::is_scene_file(p))
    {
        found.push((dir.to_path_buf(), Format::from_path(dir)));
    }
    for p in entries {
        if p.is_dir() {
            walk(&p, out, found, seen, skipped);
        } else if formats::is_source(&p) {
            // A link that resolves to nothing is still listed: its read fails with the reason.
            if std::fs::canonicalize(&p).map_or(true, |c| seen.insert(c)) {
                let format = Format::from_path(&p);
                found.push((p, format));
            }
        } else if extension(&p) != "obj" && p.file_name().is_none_or(|n| n != PROVENANCE_FILE) {
            *skipped.entry(extension(&p)).or_insert(0) += 1;
        }
    }
}
