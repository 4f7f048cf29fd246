//! Summaries of a dataset store (its `index.parquet`, docs/method.md §2.2) or of one clip file (docs/method.md §2.1),
//! as a text table or JSON.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::clip::object_uid;
use crate::error::{DataError, Result};
use crate::formats::skeletal::{ReadOptions, SkinStats, TakeInfo};
use crate::formats::{self, Format};
use crate::store::{IndexRow, Split, Status, Store, check_index, read_index};

/// Lower edge of the vertex histogram (docs/method.md §2.2 filter).
pub const HIST_MIN: u32 = 512;
/// Upper edge of the vertex histogram (docs/method.md §2.2 filter, inclusive).
pub const HIST_MAX: u32 = 4096;
/// Bins between [`HIST_MIN`] and [`HIST_MAX`].
pub const HIST_BINS: u32 = 8;

/// One bin of the vertex-count histogram: `lo ≤ N_v < hi` (the last bin includes `hi`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bin {
    pub lo: u32,
    pub hi: u32,
    pub count: usize,
}

/// Counts and distributions of a store.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// The store folder.
    pub dir: String,
    /// Index rows: stored clips plus rejected files.
    pub clips: usize,
    /// Stored clips (status "ok").
    pub ok: usize,
    /// Rejected source files.
    pub rejected: usize,
    /// Stored clips per split.
    pub train: usize,
    pub val: usize,
    /// Distinct object uids among the stored clips.
    pub objects: usize,
    /// Stored clips whose caption is empty or only whitespace (unconditional).
    pub empty_captions: usize,
    /// Stored clips whose index row has a checksum (0 for a store written before checksums: re-import to add
    /// them); `data verify` checks them.
    pub checksums: usize,
    /// Vertex counts of stored clips in [`HIST_BINS`] bins over [`HIST_MIN`]..=[`HIST_MAX`].
    pub vertex_histogram: Vec<Bin>,
    /// Stored clips below [`HIST_MIN`] / above [`HIST_MAX`] vertices.
    pub vertices_below: usize,
    pub vertices_above: usize,
    /// Frames T → number of stored clips.
    pub frames: BTreeMap<u32, usize>,
    /// Source format → number of index rows.
    pub formats: BTreeMap<String, usize>,
    /// Registry package → stored clips / distinct objects (clips with a recorded `source_package` only).
    pub packages: BTreeMap<String, usize>,
    pub package_objects: BTreeMap<String, usize>,
    /// Licence → stored clips (clips with a recorded licence only).
    pub licences: BTreeMap<String, usize>,
    /// `<shape>-<motion>` → stored clips, for ids of the form `synth-<shape>-<motion>-<seed>-<index>…`.
    pub synthetic_families: BTreeMap<String, usize>,
    /// Field of the reject reason (the text before its first ':') → rejected files.
    pub reject_reasons: BTreeMap<String, usize>,
    /// Every rejected file with its full reason.
    pub rejected_files: Vec<(String, String)>,
    /// Stored clips that move in a scene (docs/method.md §6.5); `None` when the store's records carry no scene
    /// section.
    pub scenes: Option<usize>,
    /// The shards of a sharded store, as its manifest lists them (`None`: a one-file store).
    pub shards: Option<Vec<crate::store::shards::ShardEntry>>,
}

/// Facts about one clip file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileSummary {
    pub path: String,
    pub format: String,
    pub id: String,
    pub object: String,
    pub frames: usize,
    pub vertices: usize,
    pub faces: usize,
    pub caption: String,
    /// Bounding box over all frames.
    pub bbox_min: [f32; 3],
    pub bbox_max: [f32; 3],
    /// The file's takes (empty for a single-clip format); the figures above are the first take's.
    pub takes: Vec<TakeInfo>,
    /// Animations of one frame (poses), which are not takes ([`formats::one_frame_takes`]).
    pub poses: Vec<String>,
    /// Skin weights of the first take that were renormalised or had more than 4 entries.
    pub skin: SkinStats,
}

/// What [`inspect`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Inspection {
    Store(Summary),
    File(FileSummary),
}

impl Inspection {
    /// A human-readable table.
    pub fn to_table(&self) -> String {
        match self {
            Self::Store(s) => s.to_table(),
            Self::File(f) => f.to_table(),
        }
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        // Serialising plain structs of strings, numbers and maps with string keys cannot fail.
        serde_json::to_string_pretty(self).expect("summary serialises")
    }
}

/// Inspect a store folder (one holding `clips.bin`) or a clip file / OBJ-sequence folder.
pub fn inspect(path: &Path) -> Result<Inspection> {
    if crate::store::remote::is_url(path) {
        return summarize(&crate::store::remote::local_dir(path)?).map(Inspection::Store);
    }
    if path.is_dir() && crate::store::is_store(path) {
        return summarize(path).map(Inspection::Store);
    }
    if !path.exists() {
        return Err(DataError::new(path, "file", "not found"));
    }
    summarize_file(path).map(Inspection::File)
}

/// Summarise the store in `dir` from its index, after checking that `clips.bin` holds the clips the index lists
/// (count and record sizes; [`check_index`]). A missing, truncated or mismatched `clips.bin` is an error.
pub fn summarize(dir: &Path) -> Result<Summary> {
    let rows = read_index(dir)?;
    let store = Store::open(dir)?;
    check_index(&store, &rows)?;
    let mut summary = summarize_rows(dir, &rows);
    if store.has_scenes() {
        let mut with = 0;
        for i in 0..store.len() {
            with += usize::from(store.get(i)?.scene.is_some());
        }
        summary.scenes = Some(with);
    }
    if dir.join(crate::store::MANIFEST_FILE).is_file() {
        summary.shards = Some(crate::store::shards::read_manifest(dir)?.shards);
    }
    Ok(summary)
}

/// Summarise index rows (the pure part of [`summarize`]).
pub fn summarize_rows(dir: &Path, rows: &[IndexRow]) -> Summary {
    let width = (HIST_MAX - HIST_MIN) / HIST_BINS;
    let mut vertex_histogram: Vec<Bin> = (0..HIST_BINS)
        .map(|b| Bin {
            lo: HIST_MIN + b * width,
            hi: if b + 1 == HIST_BINS {
                HIST_MAX
            } else {
                HIST_MIN + (b + 1) * width
            },
            count: 0,
        })
        .collect();
    let mut s = Summary {
        dir: dir.display().to_string(),
        clips: rows.len(),
        ok: 0,
        rejected: 0,
        train: 0,
        val: 0,
        objects: 0,
        empty_captions: 0,
        checksums: 0,
        vertex_histogram: Vec::new(),
        vertices_below: 0,
        vertices_above: 0,
        frames: BTreeMap::new(),
        formats: BTreeMap::new(),
        packages: BTreeMap::new(),
        package_objects: BTreeMap::new(),
        licences: BTreeMap::new(),
        synthetic_families: BTreeMap::new(),
        reject_reasons: BTreeMap::new(),
        rejected_files: Vec::new(),
        scenes: None,
        shards: None,
    };
    let mut objects = std::collections::HashSet::new();
    let mut package_objects = std::collections::HashSet::new();
    for r in rows {
        *s.formats.entry(r.format.clone()).or_default() += 1;
        match r.status {
            Status::Rejected => {
                s.rejected += 1;
                let field = r
                    .reason
                    .split_once(':')
                    .map_or(r.reason.as_str(), |(f, _)| f)
                    .trim()
                    .to_owned();
                *s.reject_reasons.entry(field).or_default() += 1;
                s.rejected_files.push((r.source.clone(), r.reason.clone()));
            }
            Status::Ok => {
                s.ok += 1;
                match r.split {
                    Some(Split::Train) => s.train += 1,
                    Some(Split::Val) => s.val += 1,
                    None => {}
                }
                objects.insert(r.object.as_str());
                if !r.source_package.is_empty() {
                    *s.packages.entry(r.source_package.clone()).or_default() += 1;
                    if package_objects.insert((r.source_package.as_str(), r.object.as_str())) {
                        *s.package_objects.entry(r.source_package.clone()).or_default() += 1;
                    }
                }
                if !r.licence.is_empty() {
                    *s.licences.entry(r.licence.clone()).or_default() += 1;
                }
                s.empty_captions += usize::from(r.caption.trim().is_empty());
                s.checksums += usize::from(r.checksum.is_some());
                if let Some(t) = r.frames {
                    *s.frames.entry(t).or_default() += 1;
                }
                if let Some(n) = r.vertices {
                    if n < HIST_MIN {
                        s.vertices_below += 1;
                    } else if n > HIST_MAX {
                        s.vertices_above += 1;
                    } else {
                        vertex_histogram[((n - HIST_MIN) / width).min(HIST_BINS - 1) as usize].count += 1;
                    }
                }
                if let Some(family) = synthetic_family(&r.id) {
                    *s.synthetic_families.entry(family.to_owned()).or_default() += 1;
                }
            }
        }
    }
    s.objects = objects.len();
    s.vertex_histogram = vertex_histogram;
    s
}

/// `<shape>-<motion>` of a synthetic id `synth-<shape>-<motion>-<seed>-<index>[_offset…]`, or
/// `rigged-<template>-<action>` of a rigged character's `rigged-<template>-<action>-<seed>-<index>[_offset…]`.
pub fn synthetic_family(id: &str) -> Option<&str> {
    let uid = object_uid(id);
    let rest = match uid.strip_prefix("synth-") {
        Some(rest) => rest,
        None if uid.starts_with("rigged-") => uid,
        None => return None,
    };
    let mut parts = rest.rsplitn(3, '-');
    let (_index, _seed, family) = (parts.next()?, parts.next()?, parts.next()?);
    Some(family)
}

/// Read one clip file (or OBJ-sequence folder) and describe it.
pub fn summarize_file(path: &Path) -> Result<FileSummary> {
    let format = Format::from_path(path)?;
    let takes = formats::list_takes(path)?.unwrap_or_default();
    let poses = formats::one_frame_takes(path)?;
    let taken = formats::read_take(path, &ReadOptions::default())?;
    let clip = taken.clip;
    let (lo, hi) = crate::preprocess::bounds(&clip.vertices);
    Ok(FileSummary {
        path: path.display().to_string(),
        format: format!("{format:?}"),
        object: clip.object_uid().to_owned(),
        id: clip.id,
        frames: clip.frames,
        vertices: clip.n_vertices,
        faces: clip.faces.len(),
        caption: clip.caption,
        bbox_min: lo,
        bbox_max: hi,
        takes,
        poses,
        skin: taken.stats,
    })
}

fn map_line(out: &mut String, label: &str, m: &BTreeMap<impl std::fmt::Display, usize>) {
    if m.is_empty() {
        return;
    }
    let items: Vec<String> = m.iter().map(|(k, v)| format!("{k}: {v}")).collect();
    let _ = writeln!(out, "{label:<18} {}", items.join(", "));
}

impl Summary {
    /// A human-readable table.
    pub fn to_table(&self) -> String {
        let mut o = String::new();
        // Writing into a String cannot fail.
        let _ = writeln!(o, "store              {}", self.dir);
        let _ = writeln!(
            o,
            "index rows         {} ({} ok, {} rejected)",
            self.clips, self.ok, self.rejected
        );
        let _ = writeln!(
            o,
            "split              {} train, {} val ({} objects)",
            self.train, self.val, self.objects
        );
        let _ = writeln!(o, "empty captions     {}", self.empty_captions);
        if let Some(n) = self.scenes {
            let _ = writeln!(o, "scenes             {n} of {} clips move in a scene", self.ok);
        }
        if let Some(shards) = &self.shards {
            let bytes: u64 = shards.iter().map(|s| s.bytes).sum();
            let sizes = shards.iter().map(|s| s.clips);
            let _ = writeln!(
                o,
                "shards             {} ({} to {} clips, {:.2} GB in all; manifest.json lists them)",
                shards.len(),
                sizes.clone().min().unwrap_or(0),
                sizes.max().unwrap_or(0),
                bytes as f64 / 1e9
            );
            for s in shards {
                let _ = writeln!(
                    o,
                    "  {:<16} {} clips ({} train, {} val), {} rejected, {} bytes",
                    s.path, s.clips, s.train, s.val, s.rejected, s.bytes
                );
            }
        }
        let _ = writeln!(
            o,
            "clips.bin          matches the index (count, sizes); {} of {} clips have a checksum{}",
            self.checksums,
            self.ok,
            if self.checksums < self.ok {
                " (re-import to add them)"
            } else {
                " (`data verify` checks them)"
            }
        );
        map_line(&mut o, "frames", &self.frames);
        map_line(&mut o, "formats", &self.formats);
        map_line(&mut o, "packages (clips)", &self.packages);
        map_line(&mut o, "packages (objects)", &self.package_objects);
        map_line(&mut o, "licences", &self.licences);
        let _ = writeln!(
            o,
            "vertices           below {}: {}, above {}: {}",
            HIST_MIN, self.vertices_below, HIST_MAX, self.vertices_above
        );
        let max = self.vertex_histogram.iter().map(|b| b.count).max().unwrap_or(0).max(1);
        for b in &self.vertex_histogram {
            let bar = "#".repeat(b.count * 40 / max);
            let _ = writeln!(o, "  {:>4}–{:<4} {:>8} {bar}", b.lo, b.hi, b.count);
        }
        map_line(&mut o, "synthetic", &self.synthetic_families);
        map_line(&mut o, "reject reasons", &self.reject_reasons);
        for (source, reason) in &self.rejected_files {
            let _ = writeln!(o, "  rejected {source}: {reason}");
        }
        o
    }
}

impl FileSummary {
    /// A human-readable table.
    pub fn to_table(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "file      {} ({})", self.path, self.format);
        let _ = writeln!(o, "id        {} (object {})", self.id, self.object);
        let _ = writeln!(o, "frames    {}", self.frames);
        let _ = writeln!(o, "vertices  {}", self.vertices);
        let _ = writeln!(o, "faces     {}", self.faces);
        let _ = writeln!(o, "caption   {:?}", self.caption);
        let _ = writeln!(o, "bbox      {:?} – {:?}", self.bbox_min, self.bbox_max);
        if self.skin.vertices > 0 {
            let _ = writeln!(o, "skin      {}", self.skin.line());
        }
        if !self.takes.is_empty() {
            let _ = writeln!(o, "takes     {}", self.takes.len());
            for (i, t) in self.takes.iter().enumerate() {
                let file = t
                    .file
                    .as_ref()
                    .map_or_else(String::new, |f| format!("  ({})", f.display()));
                // A rate of 0 means the file gives none (an MD3 without `animation.cfg`, frames-only formats).
                let fps = if t.fps > 0.0 {
                    format!("{:>5.1} fps", t.fps)
                } else {
                    "  fps not given".to_owned()
                };
                let _ = writeln!(o, "  {i:>3}  {:<28} {:>5} frames  {fps}{file}", t.name, t.frames);
            }
        }
        if !self.poses.is_empty() {
            let _ = writeln!(
                o,
                "poses     {} one-frame animations, not takes (a clip needs motion): {}",
                self.poses.len(),
                self.poses.join(", ")
            );
        }
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_take_without_a_rate_says_so() {
        let dir = tempfile::tempdir().unwrap();
        // An MD3 with no animation.cfg beside it: one take, no frame rate.
        let path = dir.path().join("lower.md3");
        let frames: Vec<Vec<[i16; 3]>> = (0..3i16).map(|f| vec![[0, 0, 0], [64, 0, f * 8], [0, 64, 0]]).collect();
        std::fs::write(&path, crate::formats::md3::write_test_md3(&frames, &[[0, 1, 2]])).unwrap();
        let text = inspect(&path).unwrap().to_table();
        assert!(text.contains("3 frames    fps not given"), "{text}");
        assert!(!text.contains("0.0 fps"), "{text}");
    }

    #[test]
    fn one_frame_animations_are_listed_as_poses() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("soldier.md2");
        let frame = |z: u8| vec![[0, 0, z], [10, 0, 0], [0, 10, 0]];
        let frames = [("run1", frame(0)), ("run2", frame(5)), ("salute", frame(9))];
        std::fs::write(&path, crate::formats::md2::write_md2(&frames, &[[0, 1, 2]])).unwrap();
        let summary = summarize_file(&path).unwrap();
        let text = summary.to_table();
        assert!(text.contains("poses     1 one-frame animations"), "{text}");
        assert_eq!((summary.poses, summary.takes.len()), (vec!["salute".to_owned()], 1));
    }

    fn row(id: &str, vertices: u32, split: Option<Split>, status: Status, reason: &str) -> IndexRow {
        IndexRow {
            id: id.into(),
            source: format!("/data/{id}.bin"),
            format: "bin".into(),
            frames: (status == Status::Ok).then_some(16),
            vertices: (status == Status::Ok).then_some(vertices),
            faces: (status == Status::Ok).then_some(10),
            caption: if id == "big" { String::new() } else { "a cat".into() },
            split,
            status,
            reason: reason.into(),
            licence: String::new(),
            source_package: String::new(),
            object: object_uid(id).into(),
            checksum: (status == Status::Ok).then_some(7),
        }
    }

    #[test]
    fn counts_histogram_and_families() {
        let rows = vec![
            row(
                "synth-sphere-wave-1-0_offset0_0-15",
                512,
                Some(Split::Train),
                Status::Ok,
                "",
            ),
            row(
                "synth-sphere-wave-1-1_offset0_0-15",
                959,
                Some(Split::Train),
                Status::Ok,
                "",
            ),
            row(
                "synth-torus-twist-1-2_offset0_0-15",
                4096,
                Some(Split::Val),
                Status::Ok,
                "",
            ),
            row("big", 5000, Some(Split::Train), Status::Ok, ""),
            row("bad", 0, None, Status::Rejected, "vertices: has 100 vertices"),
            IndexRow {
                source_package: "0ad-data".into(),
                licence: "CC-BY-SA-3.0".into(),
                ..row("deer_offset0_0-15", 1000, Some(Split::Train), Status::Ok, "")
            },
            IndexRow {
                source_package: "0ad-data".into(),
                licence: "CC-BY-SA-3.0".into(),
                ..row("deer_offset0_8-23", 1000, Some(Split::Train), Status::Ok, "")
            },
            IndexRow {
                source_package: "0ad-data".into(),
                ..row("bad-deer", 0, None, Status::Rejected, "frames: too short")
            },
        ];
        let s = summarize_rows(Path::new("d"), &rows);
        assert_eq!((s.clips, s.ok, s.rejected, s.train, s.val), (8, 6, 2, 5, 1));
        // Packages count stored clips and their objects (both deer windows are one object); rejects are not counted.
        assert_eq!(s.packages.get("0ad-data"), Some(&2));
        assert_eq!(s.package_objects.get("0ad-data"), Some(&1));
        assert_eq!(s.licences.get("CC-BY-SA-3.0"), Some(&2));
        assert_eq!(s.licences.len(), 1);
        assert_eq!((s.empty_captions, s.checksums), (1, 6));
        // A caption of spaces conditions on nothing, like an empty one (docs/method.md §4.4).
        let mut spaced = rows.clone();
        spaced[0].caption = " \t".into();
        assert_eq!(summarize_rows(Path::new("d"), &spaced).empty_captions, 2);
        assert_eq!(s.vertex_histogram.len(), 8);
        assert_eq!(
            s.vertex_histogram[0],
            Bin {
                lo: 512,
                hi: 960,
                count: 2
            }
        );
        assert_eq!(s.vertex_histogram[7].count, 1);
        assert_eq!(s.vertices_above, 1);
        assert_eq!(s.synthetic_families.get("sphere-wave"), Some(&2));
        assert_eq!(s.synthetic_families.get("torus-twist"), Some(&1));
        assert_eq!(s.reject_reasons.get("vertices"), Some(&1));
        let json: serde_json::Value = serde_json::from_str(&Inspection::Store(s.clone()).to_json()).unwrap();
        for key in ["clips", "ok", "rejected", "train", "val"] {
            assert!(json[key].is_u64(), "missing {key} in {json}");
        }
        assert!(
            s.to_table().contains("rejected /data/bad.bin: vertices"),
            "{}",
            s.to_table()
        );
    }

    #[test]
    fn synthetic_family_needs_the_synth_form() {
        assert_eq!(synthetic_family("synth-a-b-7-3_offset0_0-15"), Some("a-b"));
        assert_eq!(synthetic_family("cat_offset0_0-15"), None);
        assert_eq!(
            synthetic_family("rigged-bird-fly-7-3_offset0_0-15"),
            Some("rigged-bird-fly")
        );
        assert_eq!(synthetic_family("synth-x"), None);
    }
}
