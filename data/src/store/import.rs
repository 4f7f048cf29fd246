//! Import clip files (or procedural clips) into a dataset store: find sources, preprocess each window
//! (weld, filter, normalise (D1)–(D3), FPS of docs/method.md §2.5), split by object (docs/method.md §2.2), write
//! atomically.
//!
//! One bad file never aborts an import: whatever goes wrong with it (an error, a panic in a reader, more than
//! [`ImportOptions::time_limit`]) makes it a "rejected" row of the index with its reason, and the other files
//! are imported. Only problems with the output folder or an existing store abort, and then no temporary file is
//! left behind.

use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use rayon::prelude::*;

use crate::clip::object_uid;
use crate::error::{DataError, Result};
use crate::formats::skeletal::SkinStats;
use crate::limits::FRAMES;
use crate::synth::{self, SynthConfig};

use super::clips::{preprocess_windows, process_file, reason};
use super::discover::discover;
use super::jobs::{Job, Outcome, Process, run_one};
use super::options::check_p;
pub use super::options::{FILE_TIME_LIMIT, ImportOptions, Weld};
pub use super::provenance::{PROVENANCE_FILE, Provenance};
use super::shards::{ShardSpec, shard_key};

use super::{
    CLIPS_FILE, DEFAULT_P, IndexRow, Split, Status, Store, StoreWriter, StoredClip, check_index, read_index,
    write_index,
};

/// Progress callback: `(sources done, sources total)`, called after each parallel chunk.
pub type Progress<'a> = Option<&'a (dyn Fn(usize, usize) + Sync)>;

/// A source that produced no clip, and why.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Rejected {
    pub source: String,
    pub reason: String,
}

/// What an import (or synth) did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ImportReport {
    /// The store folder.
    pub dir: PathBuf,
    /// Sources processed by this run.
    pub sources: usize,
    /// Clips (windows) written from this run's sources.
    pub added: usize,
    /// Clips kept from an earlier import of other sources.
    pub kept: usize,
    /// Clips in the store now, and how they split.
    pub total: usize,
    pub train: usize,
    pub val: usize,
    /// This run's rejected sources.
    pub rejected: Vec<Rejected>,
    /// Skin weights of this run's accepted takes that were renormalised or had more than 4 entries (each
    /// take's vertices counted once, however many windows it gave).
    pub skin: SkinStats,
    /// Files met in the searched folders that are not read as clips (sidecars, textures, unknown formats), counted
    /// by lower-case extension (`""` for none).
    pub skipped: BTreeMap<String, usize>,
    /// One-frame animations of this run's files that are not takes (`source#name`; poses, not motion).
    pub poses: Vec<String>,
}

impl fmt::Display for ImportReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}: {} sources → {} clips added, {} kept; store holds {} clips ({} train, {} val); {} rejected",
            self.dir.display(),
            self.sources,
            self.added,
            self.kept,
            self.total,
            self.train,
            self.val,
            self.rejected.len()
        )?;
        if self.skin.vertices > 0 {
            writeln!(f, "  skin weights: {}", self.skin.line())?;
        }
        if !self.skipped.is_empty() {
            let by_ext: Vec<String> = self
                .skipped
                .iter()
                .map(|(ext, n)| format!("{n} × {}", if ext.is_empty() { "(no extension)" } else { ext }))
                .collect();
            let n: usize = self.skipped.values().sum();
            writeln!(
                f,
                "  {n} other files not read as clips (sidecars, textures, unknown formats): {}",
                by_ext.join(", ")
            )?;
        }
        if !self.poses.is_empty() {
            let more = self.poses.len().saturating_sub(3);
            let more = if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            };
            writeln!(
                f,
                "  {} one-frame animations not read as takes (poses, no motion): {}{more}",
                self.poses.len(),
                self.poses[..self.poses.len().min(3)].join(", ")
            )?;
        }
        for r in &self.rejected {
            writeln!(f, "  rejected {}: {}", r.source, r.reason)?;
        }
        Ok(())
    }
}

/// Import `sources` (files, or folders searched recursively for the files of
/// [`formats::SOURCE_EXTENSIONS`] and folders of `.obj` frames) into the store folder `out`; see the
/// [`crate::store`] module doc for re-imports. Every take of a file with takes becomes its own clip: id
/// `<object>_offset<take index>_0-<T−1>` (windows renumber the range), caption from the asset and take names
/// ([`crate::caption`]), source `path#take`; its `licence` and `source_package` come from the nearest
/// [`PROVENANCE_FILE`].
pub fn import(sources: &[PathBuf], out: &Path, opts: &ImportOptions) -> Result<ImportReport> {
    import_with_progress(sources, out, opts, None)
}

/// [`import`] with a progress callback.
pub fn import_with_progress(
    sources: &[PathBuf],
    out: &Path,
    opts: &ImportOptions,
    progress: Progress,
) -> Result<ImportReport> {
    opts.validate()?;
    let existing = prepare_out(out, opts.frames, opts.p)?;
    let (mut jobs, skipped) = discover(sources, out)?;
    if let Some(shard) = opts.shard {
        let roots: Vec<PathBuf> = sources.iter().filter_map(|s| std::fs::canonicalize(s).ok()).collect();
        jobs.retain(|job| match job {
            Job::File { path, .. } => shard.takes(&shard_key(path, &roots)),
            Job::Synth { source, .. } => shard.takes(source),
        });
    }
    let owned = opts.clone();
    let limits = Limits {
        frames: opts.frames,
        p: opts.p,
        time: opts.time_limit,
        scenes: false,
    };
    let report = run_jobs(
        out,
        existing,
        &jobs,
        limits,
        progress,
        Arc::new(move |job: &Job| process_file(job, &owned)),
    )?;
    Ok(ImportReport { skipped, ..report })
}

/// Write `cfg.clips` procedural clips into the store `out` with P = [`DEFAULT_P`].
pub fn write_synth(cfg: &SynthConfig, out: &Path) -> Result<ImportReport> {
    write_synth_with(cfg, out, DEFAULT_P, None)
}

/// [`write_synth`] with P FPS tokens and a progress callback. Each procedural clip is one window; its source is
/// `synth:<seed>:<index>`, so synth runs with other seeds add to the store and the same seed replaces.
pub fn write_synth_with(cfg: &SynthConfig, out: &Path, p: usize, progress: Progress) -> Result<ImportReport> {
    write_synth_windows(cfg, out, p, cfg.frames, 1, progress)
}

/// [`write_synth_with`] cutting each procedural clip into windows of `window` frames every `stride` frames
/// (docs/method.md §2.6). With `cfg.frames = 31`, `window = 16`, `stride = 15` the two windows of a clip share frame 15
/// and form a long-horizon pair (docs/method.md §2.7, P-Table 2).
pub fn write_synth_windows(
    cfg: &SynthConfig,
    out: &Path,
    p: usize,
    window: usize,
    stride: usize,
    progress: Progress,
) -> Result<ImportReport> {
    write_synth_shard(cfg, out, p, (window, stride), None, progress)
}

/// [`write_synth_windows`] (`windows` = (window, stride)) writing only the procedural clips of `shard` (by the hash
/// of their source `synth:<seed>:<index>`; the [`super::shards`] module doc), all of them when `None`.
pub fn write_synth_shard(
    cfg: &SynthConfig,
    out: &Path,
    p: usize,
    (window, stride): (usize, usize),
    shard: Option<ShardSpec>,
    progress: Progress,
) -> Result<ImportReport> {
    check_p(p, "synth options")?;
    if window < 2 || window > cfg.frames || stride == 0 || stride > FRAMES.get_usize() {
        return Err(DataError::new(
            out,
            "window",
            format!(
                "window {window} / stride {stride} do not fit clips of {} frames",
                cfg.frames
            ),
        ));
    }
    cfg.validate()?;
    let existing = prepare_out(out, window, p)?;
    let jobs: Vec<Job> = (0..cfg.clips)
        .map(|index| Job::Synth {
            source: cfg.source(index),
            index,
        })
        .filter(|job| shard.is_none_or(|s| s.takes(job.source())))
        .collect();
    let cfg = cfg.clone();
    let limits = Limits {
        frames: window,
        p,
        time: FILE_TIME_LIMIT,
        scenes: cfg.scenes,
    };
    let process = move |job: &Job| match job {
        Job::Synth { source, index } => match synth::generate_scened(&cfg, *index) {
            Ok((mut clip, scene)) => {
                clip.source = source.clone();
                match preprocess_windows(&clip, window, stride, p, scene.as_ref()) {
                    Ok(windows) => Outcome::Clips(windows, Vec::new(), SkinStats::default(), Vec::new()),
                    Err(e) => Outcome::Rejected(reason(&e, source)),
                }
            }
            Err(e) => Outcome::Rejected(reason(&e, source)),
        },
        Job::File { .. } => Outcome::Rejected("not a procedural clip".into()),
    };
    run_jobs(out, existing, &jobs, limits, progress, Arc::new(process))
}

/// Create `out`, or open the store already in it (checking that T and P agree); refuse a non-empty folder that
/// holds no store.
fn prepare_out(out: &Path, frames: usize, p: usize) -> Result<Option<(Store, Vec<IndexRow>)>> {
    if super::is_url(out) {
        return Err(DataError::new(
            out,
            "out",
            "stores are written to a local folder; put one into object storage with scripts/upload_store.py",
        ));
    }
    if out.join(super::shards::MANIFEST_FILE).exists() {
        return Err(DataError::new(
            out,
            super::shards::MANIFEST_FILE,
            "a sharded store: import into one of its shard folders with `--shard K/N`, then `data merge` again",
        ));
    }
    if out.join(CLIPS_FILE).exists() {
        let store = Store::open(out)?;
        if store.frames() != frames || store.p() != p {
            return Err(DataError::new(
                out,
                "store",
                format!(
                    "holds clips with T = {}, P = {}; this run makes T = {frames}, P = {p}: use another folder",
                    store.frames(),
                    store.p()
                ),
            ));
        }
        let rows = read_index(out)?;
        check_index(&store, &rows)?;
        return Ok(Some((store, rows)));
    }
    if out.exists() {
        let mut entries = std::fs::read_dir(out).map_err(|e| DataError::io(out, e))?;
        if let Some(entry) = entries.next() {
            let name = entry.map_err(|e| DataError::io(out, e))?.file_name();
            return Err(DataError::new(
                out,
                CLIPS_FILE,
                format!("the folder is not empty (holds {name:?}) and holds no any4d store: refusing to write into it"),
            ));
        }
    }
    std::fs::create_dir_all(out).map_err(|e| DataError::io(out, e))?;
    Ok(None)
}

/// The index row of a stored clip; called after [`StoreWriter::append`] accepted it, which checked that the
/// counts fit in u32.
fn ok_row(c: &StoredClip, format: &str, object: String, checksum: u64, provenance: &Provenance) -> IndexRow {
    let to_u32 = |v: usize| Some(v as u32);
    IndexRow {
        id: c.clip.id.clone(),
        source: c.clip.source.clone(),
        format: format.to_owned(),
        frames: to_u32(c.clip.frames),
        vertices: to_u32(c.clip.n_vertices),
        faces: to_u32(c.clip.faces.len()),
        caption: c.clip.caption.clone(),
        split: Some(c.split),
        status: Status::Ok,
        reason: String::new(),
        object,
        checksum: Some(checksum),
        licence: provenance.licence.clone(),
        source_package: provenance.source_package.clone(),
    }
}

fn rejected_row(job: &Job, source: &str, reason: String) -> IndexRow {
    let source = source.to_owned();
    let provenance = job.provenance();
    let id = Path::new(&source)
        .file_name()
        .map_or_else(|| source.clone(), |n| n.to_string_lossy().into_owned());
    IndexRow {
        object: object_uid(&id).to_owned(),
        id,
        source,
        format: job.format_name().to_owned(),
        frames: None,
        vertices: None,
        faces: None,
        caption: String::new(),
        split: None,
        status: Status::Rejected,
        reason,
        checksum: None,
        licence: provenance.licence,
        source_package: provenance.source_package,
    }
}

/// Sources processed in parallel per chunk, written in order.
const CHUNK: usize = 64;

/// The store shape of a run and its per-source time limit.
#[derive(Debug, Clone, Copy)]
struct Limits {
    frames: usize,
    p: usize,
    time: Duration,
    /// Records carry a scene section even when no file source has a scene beside it (procedural scenes).
    scenes: bool,
}

/// Rewrite the store in `out` from the kept part of `existing` plus the outcome of `jobs`.
fn run_jobs(
    out: &Path,
    existing: Option<(Store, Vec<IndexRow>)>,
    jobs: &[Job],
    limits: Limits,
    progress: Progress,
    process: Process,
) -> Result<ImportReport> {
    let replaced: HashSet<&str> = jobs.iter().map(Job::source).collect();
    // Dropped without `finish` (any error below), the writer removes its temporary file.
    // Records carry a scene section when a source has a scene (beside it, or a glTF's still meshes) or the existing
    // store's records do.
    let scenes = limits.scenes
        || existing.as_ref().is_some_and(|(store, _)| store.has_scenes())
        || jobs.iter().any(|j| match j {
            Job::File { path, .. } => super::clips::scene_of(path).is_ok_and(|s| s.is_some()),
            _ => false,
        });
    let mut writer = StoreWriter::create_with(&out.join(CLIPS_FILE), limits.frames, limits.p, scenes)?;
    let mut ok_rows = Vec::new();
    let mut rejected_rows = Vec::new();
    let mut kept = 0;
    if let Some((store, rows)) = existing {
        let (old_ok, old_rejected): (Vec<IndexRow>, Vec<IndexRow>) =
            rows.into_iter().partition(|r| r.status == Status::Ok);
        for (i, mut row) in old_ok.into_iter().enumerate() {
            if is_replaced(&replaced, &row.source) {
                continue;
            }
            let raw = store.raw(i)?;
            let id = record_id(&raw);
            if id != Some(row.id.as_str()) {
                return Err(DataError::new(
                    out,
                    "index.parquet",
                    format!(
                        "row {i} names clip {:?} but clips.bin holds {id:?} there: the store is inconsistent",
                        row.id
                    ),
                ));
            }
            let old_sum = super::checksum(&raw);
            let sum = match store.has_scenes() == scenes {
                true => writer.append_encoded(&raw, store.split(i)?)?,
                // An old store without scenes joined by sources with them: its records gain an empty scene section.
                false => writer.append(&store.get(i)?)?,
            };
            if row.checksum.is_some_and(|old| old != old_sum) {
                return Err(DataError::new(
                    out.join(CLIPS_FILE),
                    format!("clip {i} ({})", row.id),
                    "fails its checksum: the existing store is damaged; import into a new folder",
                ));
            }
            // A store written before checksums gets them for its kept clips.
            row.checksum = Some(sum);
            ok_rows.push(row);
            kept += 1;
        }
        rejected_rows.extend(old_rejected.into_iter().filter(|r| !is_replaced(&replaced, &r.source)));
    }
    let mut rejected = Vec::new();
    let mut skin = SkinStats::default();
    let mut poses = Vec::new();
    let mut added = 0;
    for (c, chunk) in jobs.chunks(CHUNK).enumerate() {
        let outcomes: Vec<Outcome> = chunk
            .par_iter()
            .map(|job| run_one(job, &process, limits.time))
            .collect();
        for (job, outcome) in chunk.iter().zip(outcomes) {
            match outcome {
                Outcome::Clips(clips, failed, stats, one_frame) => {
                    skin.add(&stats);
                    poses.extend(one_frame);
                    let provenance = job.provenance();
                    for (clip, object) in clips {
                        let sum = writer.append(&clip)?;
                        ok_rows.push(ok_row(&clip, job.format_name(), object, sum, &provenance));
                        added += 1;
                    }
                    for (source, reason) in failed {
                        rejected.push(Rejected {
                            source: source.clone(),
                            reason: reason.clone(),
                        });
                        rejected_rows.push(rejected_row(job, &source, reason));
                    }
                }
                Outcome::Rejected(reason) => {
                    rejected.push(Rejected {
                        source: job.source().to_owned(),
                        reason: reason.clone(),
                    });
                    rejected_rows.push(rejected_row(job, job.source(), reason));
                }
            }
        }
        if let Some(f) = progress {
            f((c * CHUNK + chunk.len()).min(jobs.len()), jobs.len());
        }
    }
    writer.finish()?;
    let val = ok_rows.iter().filter(|r| r.split == Some(Split::Val)).count();
    let total = ok_rows.len();
    ok_rows.extend(rejected_rows);
    write_index(out, &ok_rows)?;
    Ok(ImportReport {
        dir: out.to_path_buf(),
        sources: jobs.len(),
        added,
        kept,
        total,
        train: total - val,
        val,
        rejected,
        skin,
        skipped: BTreeMap::new(),
        poses,
    })
}

/// Whether an index row's source (`path` or `path#take`) belongs to a source of this run.
fn is_replaced(replaced: &HashSet<&str>, source: &str) -> bool {
    replaced.contains(source) || replaced.contains(super::shards::source_base(source))
}

/// The id at the start of an encoded record, if it is well formed.
fn record_id(raw: &[u8]) -> Option<&str> {
    let len = u32::from_le_bytes(raw.get(..4)?.try_into().ok()?) as usize;
    std::str::from_utf8(raw.get(4..4 + len)?).ok()
}
