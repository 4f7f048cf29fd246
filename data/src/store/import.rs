//! Import clip files (or procedural clips) into a dataset store: find sources, preprocess each window
//! (weld, filter, normalise (D1)–(D3), FPS of SPEC §2.5), split by object (SPEC §2.2), write atomically.
//!
//! One bad file never aborts an import: it becomes a "rejected" row of the index with its reason. Only problems
//! with the output folder or an existing store abort.

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::caption;
use crate::clip::{Clip, object_uid};
use crate::error::{DataError, Result};
use crate::formats::skeletal::{self, ReadOptions, SkinStats, TakeSel};
use crate::formats::{self, Format};
use crate::fps::farthest_point_sampling;
use crate::preprocess::{self, VertexFilter};
use crate::synth::{self, SynthConfig};

use super::{
    CLIPS_FILE, DEFAULT_P, IndexRow, SPLIT_SEED, Split, Status, Store, StoreWriter, StoredClip, read_index, write_index,
};

/// Vertex welding before anything else (SPEC §2.1 sources with split seams).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Weld {
    /// Keep the file's vertices as they are (default).
    #[default]
    Off,
    /// Merge vertices closer than this distance (in file units).
    Eps(f32),
}

/// How files become store clips.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Accepted vertex counts (SPEC §2.2: 512..=4096).
    pub filter: VertexFilter,
    /// Window length T (SPEC §2.6: 16).
    pub frames: usize,
    /// Frames between window starts (SPEC §2.6: 1).
    pub stride: usize,
    /// Welding (default off).
    pub weld: Weld,
    /// FPS tokens P (SPEC §2.5: 512). A clip with fewer vertices gets its FPS order repeated cyclically
    /// (see [`farthest_point_sampling`]); the default filter rules that out.
    pub p: usize,
    /// Longest take read from a file with takes, in frames: a longer one is refused before its frames are
    /// baked (default [`skeletal::MAX_FRAMES`]).
    pub max_frames: usize,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            filter: VertexFilter::default(),
            frames: 16,
            stride: 1,
            weld: Weld::Off,
            p: DEFAULT_P,
            max_frames: skeletal::MAX_FRAMES,
        }
    }
}

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
        for r in &self.rejected {
            writeln!(f, "  rejected {}: {}", r.source, r.reason)?;
        }
        Ok(())
    }
}

/// What one source turned into: its clips (windows with their object uid), for a file with takes the takes
/// that failed (`source#take`, reason), and the skin-weight counts of the takes that were accepted. A source
/// that produced nothing is `Rejected`.
enum Outcome {
    Clips(Vec<(StoredClip, String)>, Vec<(String, String)>, SkinStats),
    Rejected(String),
}

/// Where a source comes from: the package and licence recorded per clip in `index.parquet`, and an optional
/// readable asset name for captions. Read from the nearest [`PROVENANCE_FILE`] in the source's folder or above.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
pub struct Provenance {
    #[serde(default)]
    pub source_package: String,
    #[serde(default)]
    pub licence: String,
    /// Readable asset name ("female soldier") for the captions of files in this folder.
    #[serde(default)]
    pub asset: Option<String>,
}

/// File name of a provenance sidecar: JSON `{"source_package": …, "licence": …, "asset": …}`.
pub const PROVENANCE_FILE: &str = "any4d-source.json";

/// The provenance of `path`: the nearest [`PROVENANCE_FILE`] in its folder or above (cached per folder).
fn provenance_of(path: &Path, cache: &mut HashMap<PathBuf, Result<Provenance>>) -> Result<Provenance> {
    let mut dir = path.parent();
    let mut seen = Vec::new();
    let found = loop {
        let Some(d) = dir else { break Ok(Provenance::default()) };
        if let Some(p) = cache.get(d) {
            break p.clone();
        }
        seen.push(d.to_path_buf());
        let file = d.join(PROVENANCE_FILE);
        if file.is_file() {
            break std::fs::read(&file)
                .map_err(|e| DataError::io(&file, e))
                .and_then(|b| serde_json::from_slice(&b).map_err(|e| DataError::new(&file, "json", e.to_string())));
        }
        dir = d.parent();
    };
    for d in seen {
        cache.insert(d, found.clone());
    }
    found
}

/// One unit of work: a file or folder found under the sources, or one procedural clip.
enum Job {
    File {
        source: String,
        path: PathBuf,
        format: Result<Format>,
        provenance: Result<Provenance>,
    },
    Synth {
        source: String,
        index: usize,
    },
}

impl Job {
    fn source(&self) -> &str {
        match self {
            Job::File { source, .. } | Job::Synth { source, .. } => source,
        }
    }

    fn format_name(&self) -> &'static str {
        match self {
            Job::File { format: Ok(f), .. } => f.name(),
            Job::File { format: Err(_), .. } => "",
            Job::Synth { .. } => "synth",
        }
    }

    fn provenance(&self) -> Provenance {
        match self {
            Job::File { provenance: Ok(p), .. } => p.clone(),
            _ => Provenance::default(),
        }
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
    check_options(opts)?;
    let existing = prepare_out(out, opts.frames, opts.p)?;
    let jobs = discover(sources, out)?;
    run_jobs(out, existing, &jobs, opts.frames, opts.p, progress, |job| {
        process_file(job, opts)
    })
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
/// (SPEC §2.6). With `cfg.frames = 31`, `window = 16`, `stride = 15` the two windows of a clip share frame 15 and
/// form a long-horizon pair (SPEC §2.7, P-Table 2).
pub fn write_synth_windows(
    cfg: &SynthConfig,
    out: &Path,
    p: usize,
    window: usize,
    stride: usize,
    progress: Progress,
) -> Result<ImportReport> {
    if p == 0 {
        return Err(DataError::new(out, "p", "needs at least 1 FPS token"));
    }
    if window < 2 || window > cfg.frames || stride == 0 {
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
            source: format!("synth:{}:{index}", cfg.seed),
            index,
        })
        .collect();
    run_jobs(out, existing, &jobs, window, p, progress, |job| match job {
        Job::Synth { source, index } => match synth::generate_one(cfg, *index) {
            Ok(mut clip) => {
                clip.source = source.clone();
                Outcome::Clips(
                    preprocess_windows(&clip, window, stride, p),
                    Vec::new(),
                    SkinStats::default(),
                )
            }
            Err(e) => Outcome::Rejected(reason(&e, source)),
        },
        Job::File { .. } => Outcome::Rejected("not a procedural clip".into()),
    })
}

fn check_options(opts: &ImportOptions) -> Result<()> {
    let err = |field: &str, reason: String| Err(DataError::new("import options", field, reason));
    if opts.frames < 2 {
        return err(
            "frames",
            format!("a window needs at least 2 frames, got {}", opts.frames),
        );
    }
    if opts.stride == 0 {
        return err("stride", "must be at least 1".into());
    }
    if opts.p == 0 {
        return err("p", "needs at least 1 FPS token".into());
    }
    if opts.max_frames < opts.frames {
        return err(
            "max_frames",
            format!(
                "{} is shorter than the window length {}: no take could become a clip",
                opts.max_frames, opts.frames
            ),
        );
    }
    if opts.filter.min > opts.filter.max {
        return err(
            "vertex filter",
            format!("min {} > max {}", opts.filter.min, opts.filter.max),
        );
    }
    if let Weld::Eps(e) = opts.weld
        && !(e.is_finite() && e >= 0.0)
    {
        return err("weld", format!("epsilon {e} must be finite and ≥ 0"));
    }
    Ok(())
}

/// Create `out`, or open the store already in it (checking that T and P agree); refuse a non-empty folder that
/// holds no store.
fn prepare_out(out: &Path, frames: usize, p: usize) -> Result<Option<(Store, Vec<IndexRow>)>> {
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
        let ok = rows.iter().filter(|r| r.status == Status::Ok).count();
        if ok != store.len() {
            return Err(DataError::new(
                out,
                "index.parquet",
                format!(
                    "lists {ok} stored clips but clips.bin holds {}: the store is inconsistent",
                    store.len()
                ),
            ));
        }
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

/// Find import jobs under `sources`, sorted and deduplicated by canonical path; skips the output folder and any
/// folder that holds a store.
fn discover(sources: &[PathBuf], out: &Path) -> Result<Vec<Job>> {
    let out_canon = std::fs::canonicalize(out).map_err(|e| DataError::io(out, e))?;
    let mut found: Vec<(PathBuf, Result<Format>)> = Vec::new();
    for src in sources {
        match std::fs::canonicalize(src) {
            Err(e) => found.push((src.clone(), Err(DataError::io(src, e)))),
            Ok(path) if path.is_dir() => {
                if path.join(CLIPS_FILE).exists() {
                    found.push((
                        path,
                        Err(DataError::new(
                            src,
                            CLIPS_FILE,
                            "this folder is an any4d store, not a source",
                        )),
                    ));
                } else {
                    walk(&path, &out_canon, &mut found);
                }
            }
            Ok(path) => {
                let format = Format::from_path(&path);
                found.push((path, format));
            }
        }
    }
    found.sort_by(|a, b| a.0.cmp(&b.0));
    found.dedup_by(|a, b| a.0 == b.0);
    let mut cache = HashMap::new();
    Ok(found
        .into_iter()
        .map(|(path, format)| Job::File {
            source: path.display().to_string(),
            provenance: provenance_of(&path, &mut cache),
            path,
            format,
        })
        .collect())
}

/// Recursively collect clip files and OBJ-sequence folders under `dir`. Unreadable folders become rejected jobs.
fn walk(dir: &Path, out: &Path, found: &mut Vec<(PathBuf, Result<Format>)>) {
    if dir == out || dir.join(CLIPS_FILE).exists() {
        return;
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
    let ext = |p: &Path| p.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if entries.iter().any(|p| p.is_file() && ext(p).as_deref() == Some("obj")) {
        found.push((dir.to_path_buf(), Format::from_path(dir)));
    }
    for p in entries {
        if p.is_dir() {
            walk(&p, out, found);
        } else if formats::is_source(&p) {
            let format = Format::from_path(&p);
            found.push((p, format));
        }
    }
}

/// The reason text of a rejection: `field: reason`, prefixed by the file when it is not the source itself.
fn reason(e: &DataError, source: &str) -> String {
    if e.path == source {
        format!("{}: {}", e.field, e.reason)
    } else {
        e.to_string()
    }
}

/// The reason text of a rejected take: `field: reason`, followed by the file in parentheses when it is neither
/// the source nor the take (an animation file beside the mesh), so that the field always comes first.
fn take_reason(e: &DataError, source: &str, take_source: &str) -> String {
    if e.path == source || e.path == take_source {
        format!("{}: {}", e.field, e.reason)
    } else {
        format!("{}: {} (in {})", e.field, e.reason, e.path)
    }
}

fn process_file(job: &Job, opts: &ImportOptions) -> Outcome {
    let Job::File {
        source,
        path,
        format,
        provenance,
    } = job
    else {
        return Outcome::Rejected("not a file".into());
    };
    let format = match format {
        Ok(f) => *f,
        Err(e) => return Outcome::Rejected(reason(e, source)),
    };
    if let Err(e) = provenance {
        return Outcome::Rejected(reason(e, source));
    }
    if !format.has_takes() {
        return match formats::read_clip(path).and_then(|c| accept(c, source.clone(), opts)) {
            Ok(windows) => Outcome::Clips(windows, Vec::new(), SkinStats::default()),
            Err(e) => Outcome::Rejected(reason(&e, source)),
        };
    }
    let takes = match formats::list_takes(path) {
        Ok(t) => t.unwrap_or_default(),
        Err(e) => return Outcome::Rejected(reason(&e, source)),
    };
    if takes.is_empty() {
        return Outcome::Rejected("animations: no animation: a static mesh is not a clip".into());
    }
    let asset = job.provenance().asset.unwrap_or_else(|| caption::asset_of_path(path));
    let object = object_name(path);
    let mut clips = Vec::new();
    let mut failed = Vec::new();
    let mut skin = SkinStats::default();
    for (k, take) in takes.iter().enumerate() {
        let take_source = format!("{source}#{}", take.name);
        let read = formats::read_take(
            path,
            &ReadOptions {
                take: TakeSel::Index(k),
                max_frames: opts.max_frames,
            },
        );
        let result = read.and_then(|t| {
            let mut clip = t.clip;
            clip.id = format!("{object}_offset{k}_0-{}", clip.frames - 1);
            clip.caption = caption::caption(&asset, &take.name);
            Ok((accept(clip, take_source.clone(), opts)?, t.stats))
        });
        match result {
            Ok((w, stats)) => {
                clips.extend(w);
                skin.add(&stats);
            }
            Err(e) => failed.push((take_source.clone(), take_reason(&e, source, &take_source))),
        }
    }
    if clips.is_empty() {
        let why: Vec<String> = failed
            .iter()
            .take(3)
            .map(|(s, r)| format!("{}: {r}", s.rsplit_once('#').map_or(s.as_str(), |(_, take)| take)))
            .collect();
        let more = failed.len().saturating_sub(3);
        let more = if more > 0 {
            format!("; {more} more")
        } else {
            String::new()
        };
        return Outcome::Rejected(format!(
            "takes: none of {} became a clip ({}{more})",
            failed.len(),
            why.join("; ")
        ));
    }
    Outcome::Clips(clips, failed, skin)
}

/// The object uid of a file with takes: its last two folders and stem, lower-case, `[a-z0-9]` runs joined by
/// `-` (`…/actors/drone/mesh.md5mesh` → `actors-drone-mesh`), so that all takes of one asset share a split and
/// the uid does not depend on where the tree was unpacked.
fn object_name(path: &Path) -> String {
    let comps: Vec<String> = path
        .components()
        .rev()
        .take(3)
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .split('.')
                .next()
                .unwrap_or_default()
                .to_ascii_lowercase()
        })
        .collect();
    let joined = comps.into_iter().rev().collect::<Vec<_>>().join("-");
    let mut out = String::new();
    for c in joined.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c);
        } else if !out.ends_with('-') && !out.is_empty() {
            out.push('-');
        }
    }
    out.trim_end_matches('-').to_owned()
}

/// Weld, filter and cut one clip into preprocessed windows.
fn accept(mut clip: Clip, source: String, opts: &ImportOptions) -> Result<Vec<(StoredClip, String)>> {
    clip.source = source;
    if let Weld::Eps(eps) = opts.weld {
        clip = preprocess::weld(&clip, eps);
    }
    opts.filter.check(&clip)?;
    if clip.frames < opts.frames {
        return Err(DataError::new(
            &clip.source,
            "frames",
            format!(
                "clip {} has {} frames, fewer than the window length {}",
                clip.id, clip.frames, opts.frames
            ),
        ));
    }
    Ok(preprocess_windows(&clip, opts.frames, opts.stride, opts.p))
}

/// Cut `clip` into windows, normalise each by its frame 0 (D1)–(D3), run FPS on normalised frame 0 (SPEC §2.5)
/// and assign the split of the clip's object (SPEC §2.2). Returns each window with its object uid.
fn preprocess_windows(clip: &Clip, frames: usize, stride: usize, p: usize) -> Vec<(StoredClip, String)> {
    // The uid of the whole clip, so every window of one animation shares its split.
    let object = object_uid(&clip.id).to_owned();
    let split = Split::of_object(&object, SPLIT_SEED);
    preprocess::windows(clip, frames, stride)
        .iter()
        .map(|w| {
            let (clip, normalization) = preprocess::normalize(w);
            let fps = farthest_point_sampling(clip.frame(0), p);
            (
                StoredClip {
                    clip,
                    fps,
                    normalization,
                    split,
                },
                object.clone(),
            )
        })
        .collect()
}

/// The index row of a stored clip; called after [`StoreWriter::append`] accepted it, which checked that the
/// counts fit in u32.
fn ok_row(c: &StoredClip, format: &str, object: String, provenance: &Provenance) -> IndexRow {
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
        licence: provenance.licence,
        source_package: provenance.source_package,
    }
}

/// Sources processed in parallel per chunk, written in order.
const CHUNK: usize = 64;

/// Rewrite the store in `out` from the kept part of `existing` plus the outcome of `jobs`.
fn run_jobs(
    out: &Path,
    existing: Option<(Store, Vec<IndexRow>)>,
    jobs: &[Job],
    frames: usize,
    p: usize,
    progress: Progress,
    process: impl Fn(&Job) -> Outcome + Sync,
) -> Result<ImportReport> {
    let replaced: HashSet<&str> = jobs.iter().map(Job::source).collect();
    let mut writer = StoreWriter::create(&out.join(CLIPS_FILE), frames, p)?;
    let mut ok_rows = Vec::new();
    let mut rejected_rows = Vec::new();
    let mut kept = 0;
    if let Some((store, rows)) = existing {
        let (old_ok, old_rejected): (Vec<IndexRow>, Vec<IndexRow>) =
            rows.into_iter().partition(|r| r.status == Status::Ok);
        for (i, row) in old_ok.into_iter().enumerate() {
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
            writer.append_encoded(&raw, store.split(i)?)?;
            ok_rows.push(row);
            kept += 1;
        }
        rejected_rows.extend(old_rejected.into_iter().filter(|r| !is_replaced(&replaced, &r.source)));
    }
    let mut rejected = Vec::new();
    let mut skin = SkinStats::default();
    let mut added = 0;
    for (c, chunk) in jobs.chunks(CHUNK).enumerate() {
        let outcomes: Vec<Outcome> = chunk.par_iter().map(&process).collect();
        for (job, outcome) in chunk.iter().zip(outcomes) {
            match outcome {
                Outcome::Clips(clips, failed, stats) => {
                    skin.add(&stats);
                    let provenance = job.provenance();
                    for (clip, object) in clips {
                        writer.append(&clip)?;
                        ok_rows.push(ok_row(&clip, job.format_name(), object, &provenance));
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
    })
}

/// Whether an index row's source (`path` or `path#take`) belongs to a source of this run.
fn is_replaced(replaced: &HashSet<&str>, source: &str) -> bool {
    replaced.contains(source) || source.rsplit_once('#').is_some_and(|(path, _)| replaced.contains(path))
}

/// The id at the start of an encoded record, if it is well formed.
fn record_id(raw: &[u8]) -> Option<&str> {
    let len = u32::from_le_bytes(raw.get(..4)?.try_into().ok()?) as usize;
    std::str::from_utf8(raw.get(4..4 + len)?).ok()
}
