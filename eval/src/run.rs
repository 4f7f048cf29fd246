//! `any4d eval run` / `any4d eval render` as library calls (docs/method.md §6–§7, P-Tables 1, 2, 4, 5): build or load
//! the manifest, run every method on it, write per-clip parquet, Markdown/CSV summaries, plots and predictions.
//!
//! Methods arrive already built ([`Method`] trait objects): training-free ones come from [`vertex_methods`], the
//! RF methods are built by the caller from its checkpoints (only `train` reads run folders).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use any4d_data::{Clip, DataError};
use indicatif::{ProgressBar, ProgressStyle};

use crate::baselines::VertexBaseline;
use crate::methods::{Method, MethodKind, VertexMethod, complete_and_score, metrics_map};
use crate::metrics::{Motion, evaluate_clip, replace_keyframes, vae_reconstruction};
use crate::plot::{Series, line_plot};
use crate::protocol::{Manifest, ManifestOptions, Placement, StoreSource, noise_seed, write_atomic};
use crate::render::{ExportFormat, StripOptions, export_sequence, write_strip};
use crate::rollout::{OverlapSource, RolloutSpec, rollout, seam_jerk};
use crate::tables::{
    ClipRecord, SummaryRow, TableHeader, TableKind, TimingRecord, csv, markdown, read_clip_parquet, summarize,
    timing_tables, write_clip_parquet,
};

type Result<T, E = DataError> = std::result::Result<T, E>;

/// A VAE (or any encode → decode pair) for P-Table 5.
pub trait Reconstructor {
    /// Row label, e.g. `framewise` or `sequencewise`.
    fn label(&self) -> String;
    /// Encode and decode every frame of a normalised clip.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N]` rows; returns `[T, N]` rows.
    fn reconstruct(&self, clip: &Clip) -> Result<Vec<[f32; 3]>>;
}

/// Everything `any4d eval run` needs.
pub struct RunOptions {
    /// Which table.
    pub protocol: TableKind,
    /// Dataset store folder.
    pub data: PathBuf,
    /// Output folder (created; existing result files in it are replaced).
    pub out: PathBuf,
    /// Methods to compare (tables 1, 2, 4), in table order.
    pub methods: Vec<Box<dyn Method>>,
    /// VAEs to compare (table 5).
    pub vaes: Vec<Box<dyn Reconstructor>>,
    /// Items in the manifest (100).
    pub clips: usize,
    /// Base noise seeds ([42]; X8: 42..=46).
    pub seeds: Vec<u64>,
    /// Keyframe placement of table 1 (X4); table 2 always uses keyframes every 15 frames.
    pub placement: Placement,
    /// Reuse this manifest instead of drawing one (it is copied next to the results).
    pub manifest: Option<PathBuf>,
    /// Reference of stage 2 in table 2 (docs/method.md §7, A8).
    pub overlap_source: OverlapSource,
    /// Predictions of the first `export_items` items are saved and drawn as PNG strips.
    pub export_items: usize,
    /// Names method checkpoints, text encoder and device in the table header (data and manifest are filled in).
    pub header: TableHeader,
    /// Vertex counts of table 4 (512, 1024, 2048, 4096).
    pub timing_vertices: Vec<usize>,
    /// Frame counts of table 4 (16, 31).
    pub timing_frames: Vec<usize>,
    /// Timed repetitions per size (10, after one warm-up).
    pub timing_reps: usize,
    /// Show a progress bar over clips on stderr.
    pub progress: bool,
}

impl RunOptions {
    /// Defaults of docs/method.md §6.1 for `protocol` on the store `data`, writing to `out`, with no methods yet.
    pub fn new(protocol: TableKind, data: PathBuf, out: PathBuf) -> Self {
        Self {
            protocol,
            data,
            out,
            methods: Vec::new(),
            vaes: Vec::new(),
            clips: 100,
            seeds: vec![crate::protocol::MANIFEST_SEED],
            placement: Placement::Random { k_extra_max: 3 },
            manifest: None,
            overlap_source: OverlapSource::GroundTruth,
            export_items: 4,
            header: TableHeader::default(),
            timing_vertices: vec![512, 1024, 2048, 4096],
            timing_frames: vec![16, 31],
            timing_reps: 10,
            progress: true,
        }
    }
}

/// What a protocol run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct TableReport {
    pub kind: TableKind,
    /// Summary rows (empty for table 4, whose rows are timings).
    pub rows: Vec<SummaryRow>,
    /// The Markdown summary (also written to `summary.md`).
    pub markdown: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// The training-free methods by kind; RF kinds are an error here (the caller builds them from checkpoints).
pub fn vertex_methods(kinds: &[MethodKind]) -> Result<Vec<Box<dyn Method>>> {
    kinds
        .iter()
        .map(|k| match k {
            MethodKind::Lerp => Ok(Box::new(VertexMethod(VertexBaseline::Linear)) as Box<dyn Method>),
            MethodKind::StaticNearest => Ok(Box::new(VertexMethod(VertexBaseline::NearestKeyframe)) as Box<dyn Method>),
            other => Err(DataError::new(
                "methods",
                other.label(),
                "needs trained checkpoints (--rf / --baseline-rf / --vae)",
            )),
        })
        .collect()
}

/// A saved prediction (for strips and export): item, method, keyframes, seed and `[T, N]` rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    pub item: usize,
    pub method: String,
    pub keyframes: Vec<usize>,
    pub seed: u64,
    pub vertices: Vec<[f32; 3]>,
}

fn progress_bar(show: bool, len: usize, what: &str) -> Result<ProgressBar> {
    if !show {
        return Ok(ProgressBar::hidden());
    }
    let style = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} clips, {per_sec}, ETA {eta}")
        .map_err(|e| DataError::new("progress bar", "template", e.to_string()))?;
    let bar = ProgressBar::new(len as u64);
    bar.set_style(style.progress_chars("=> "));
    bar.set_message(what.to_string());
    Ok(bar)
}

/// Run the methods over a manifest (tables 1 and 2) and return per-clip records and the kept predictions.
pub fn evaluate(
    source: &StoreSource,
    manifest: &Manifest,
    methods: &[Box<dyn Method>],
    overlap_source: OverlapSource,
    keep_items: usize,
    show_progress: bool,
) -> Result<(Vec<ClipRecord>, Vec<Prediction>)> {
    let bar = progress_bar(show_progress, manifest.clips.len(), "evaluating")?;
    let mut records = Vec::new();
    let mut kept = Vec::new();
    for (i, item) in manifest.clips.iter().enumerate() {
        let (gt, captions) = source.item(item, manifest.frames)?;
        for keyframes in &item.keyframes {
            for &base in &manifest.seeds {
                let seed = noise_seed(base, i);
                for method in methods {
                    let label = method.kind().label();
                    let (prediction, metrics) = if manifest.frames <= RolloutSpec::paper().window {
                        let s = complete_and_score(method.as_ref(), &gt, keyframes, &captions[0], seed)?;
                        (s.prediction, metrics_map(&s.metrics))
                    } else {
                        long_horizon(method.as_ref(), &gt, keyframes, &captions, seed, overlap_source)?
                    };
                    records.push(ClipRecord {
                        method: label.clone(),
                        placement: manifest.placement.label(),
                        k_extra: keyframes.len().saturating_sub(2),
                        seed: base,
                        item: i,
                        clip_id: item.clip.id.clone(),
                        metrics,
                    });
                    if i < keep_items {
                        kept.push(Prediction {
                            item: i,
                            method: label,
                            keyframes: keyframes.clone(),
                            seed: base,
                            vertices: prediction,
                        });
                    }
                }
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok((records, kept))
}

/// A prediction and its metrics by name.
type Scored = (Vec<[f32; 3]>, BTreeMap<String, f64>);

/// One long-horizon generation (docs/method.md §7) scored by (E1)–(E7) over 𝒰 = {0..30} \ {0, 15, 30} plus the seam
/// jerk.
fn long_horizon(
    method: &dyn Method,
    gt: &Clip,
    keyframes: &[usize],
    captions: &[String],
    seed: u64,
    overlap_source: OverlapSource,
) -> Result<Scored> {
    let spec = RolloutSpec {
        overlap_source,
        ..RolloutSpec::paper()
    };
    let prompts: Vec<&str> = captions.iter().map(String::as_str).collect();
    let n = gt.n_vertices;
    let label = method.kind().label();
    let r = rollout(&gt.vertices, n, keyframes, &prompts, spec, |w| {
        let window = Clip::new(
            &gt.id,
            w.vertices.clone(),
            spec.window,
            n,
            gt.faces.clone(),
            w.caption,
            &gt.source,
        )?;
        method.complete(&window, &w.keyframes, w.caption, seed.wrapping_add(w.index as u64))
    })?;
    let err = |e: crate::metrics::EvalError| DataError::new(&gt.id, &label, e.to_string());
    let pred = Motion::new(&r.vertices, gt.frames, n).map_err(err)?;
    let truth = Motion::from_clip(gt).map_err(err)?;
    let mut metrics = metrics_map(&evaluate_clip(pred, truth, keyframes).map_err(err)?);
    let assembled = replace_keyframes(pred, truth, keyframes).map_err(err)?;
    let (mut sum_p, mut sum_g, mut seams) = (0.0, 0.0, 0usize);
    for &s in &r.starts[1..] {
        if let (Some(p), Some(g)) = (
            seam_jerk(&assembled, n, s, 2, 1.0),
            seam_jerk(&gt.vertices, n, s, 2, 1.0),
        ) {
            sum_p += p;
            sum_g += g;
            seams += 1;
        }
    }
    let seams = seams.max(1) as f64;
    metrics.insert("seam_jerk".into(), sum_p / seams);
    metrics.insert("seam_jerk_gt".into(), sum_g / seams);
    metrics.insert("seam_jerk_ratio".into(), sum_p / sum_g);
    Ok((r.vertices, metrics))
}

/// `any4d eval run`: build (or load) the manifest, evaluate, and write `manifest.json`, `clips.parquet`,
/// `summary.md`, `summary.csv`, `rmse_vs_kx.png` (table 1), predictions and strips of the first items.
pub fn run_protocol(opts: &RunOptions) -> Result<TableReport> {
    std::fs::create_dir_all(&opts.out).map_err(|e| DataError::io(&opts.out, e))?;
    match opts.protocol {
        TableKind::Table1 | TableKind::Table2 => run_completion(opts),
        TableKind::Table4 => run_timing(opts),
        TableKind::Table5 => run_reconstruction(opts),
    }
}

fn header_for(opts: &RunOptions, manifest_path: &Path) -> TableHeader {
    let mut h = opts.header.clone();
    if h.data.is_empty() {
        h.data = format!("{} (validation split)", opts.data.display());
    }
    h.manifest = manifest_path.display().to_string();
    if h.text_encoder.is_empty() {
        h.text_encoder = "none (no method reads text)".into();
    }
    for m in &opts.methods {
        h.checkpoints.entry(m.kind().label()).or_insert_with(|| "none".into());
    }
    h
}

fn write_text(path: &Path, text: &str, files: &mut Vec<PathBuf>) -> Result<()> {
    write_atomic(path, text.as_bytes())?;
    files.push(path.to_path_buf());
    Ok(())
}

fn run_completion(opts: &RunOptions) -> Result<TableReport> {
    if opts.methods.is_empty() {
        return Err(DataError::new("eval run", "methods", "no methods to evaluate"));
    }
    let source = StoreSource::open(&opts.data)?;
    let manifest_path = opts.out.join("manifest.json");
    let manifest = match &opts.manifest {
        Some(path) => Manifest::load(path)?,
        None => {
            let base = if opts.protocol == TableKind::Table2 {
                ManifestOptions::table2(opts.data.display().to_string())
            } else {
                ManifestOptions {
                    placement: opts.placement,
                    ..ManifestOptions::table1(opts.data.display().to_string())
                }
            };
            let mo = ManifestOptions {
                n_clips: opts.clips,
                seeds: opts.seeds.clone(),
                ..base
            };
            Manifest::build(&source.candidates(mo.frames), &mo, &opts.data.display().to_string())?
        }
    };
    let mut files = Vec::new();
    manifest.save(&manifest_path)?;
    files.push(manifest_path.clone());
    let (records, kept) = evaluate(
        &source,
        &manifest,
        &opts.methods,
        opts.overlap_source,
        opts.export_items,
        opts.progress,
    )?;
    let parquet = opts.out.join("clips.parquet");
    write_clip_parquet(&records, &parquet)?;
    files.push(parquet);
    let rows = summarize(&records, opts.protocol)?;
    let header = header_for(opts, &manifest_path);
    let md = markdown(opts.protocol, &rows, &header);
    write_text(&opts.out.join("summary.md"), &md, &mut files)?;
    write_text(
        &opts.out.join("summary.csv"),
        &csv(opts.protocol, &rows, &header),
        &mut files,
    )?;
    if opts.protocol == TableKind::Table1 && matches!(manifest.placement, Placement::Random { .. }) {
        let path = opts.out.join("rmse_vs_kx.png");
        plot_rmse_vs_kx(&rows, &path)?;
        files.push(path);
    }
    for item in 0..opts.export_items.min(manifest.clips.len()) {
        let (gt, _) = source.item(&manifest.clips[item], manifest.frames)?;
        let preds: Vec<&Prediction> = kept.iter().filter(|p| p.item == item).collect();
        files.extend(write_item_outputs(&gt, &preds, &opts.out)?);
    }
    Ok(TableReport {
        kind: opts.protocol,
        rows,
        markdown: md,
        files,
    })
}

/// PNG strips (`strips/`) and exported sequences (`predictions/`: `.bin`, OBJ folder, `.glb`) of one item, one per
/// (method, keyframe set, seed). File stems: `item<i>_<method>_k<K_x>_seed<s>`.
fn write_item_outputs(gt: &Clip, preds: &[&Prediction], out: &Path) -> Result<Vec<PathBuf>> {
    let strips = out.join("strips");
    std::fs::create_dir_all(&strips).map_err(|e| DataError::io(&strips, e))?;
    let mut files = Vec::new();
    for p in preds {
        let stem = prediction_stem(p.item, &p.method, p.keyframes.len().saturating_sub(2), p.seed);
        let pred = Clip::new(
            &gt.id,
            p.vertices.clone(),
            gt.frames,
            gt.n_vertices,
            gt.faces.clone(),
            &gt.caption,
            &gt.source,
        )?;
        let path = strips.join(format!("{stem}.png"));
        let opts = StripOptions {
            prediction_label: p.method.clone(),
            ..StripOptions::default()
        };
        write_strip(gt, &pred, &p.keyframes, &opts, &path)?;
        files.push(path);
        files.extend(export_sequence(
            &pred,
            &out.join("predictions"),
            &stem,
            &ExportFormat::ALL,
        )?);
    }
    Ok(files)
}

/// `item<i>_<method>_k<K_x>_seed<s>`.
fn prediction_stem(item: usize, method: &str, k_extra: usize, seed: u64) -> String {
    format!("item{item:03}_{method}_k{k_extra}_seed{seed}")
}

/// RMSE × 100 against K_x, one line per method, 95 % CI bars when there are several seeds.
pub fn plot_rmse_vs_kx(rows: &[SummaryRow], path: &Path) -> Result<()> {
    let mut series: Vec<Series> = Vec::new();
    for r in rows {
        let (mean, ci) = (r.values[0].mean * 100.0, r.values[0].ci95.map(|c| c * 100.0));
        match series.iter_mut().find(|s| s.label == r.method) {
            Some(s) => {
                s.points.push((r.k_extra as f64, mean));
                if let Some(e) = s.errors.as_mut() {
                    e.push(ci.unwrap_or(0.0));
                }
            }
            None => series.push(Series {
                label: r.method.clone(),
                points: vec![(r.k_extra as f64, mean)],
                errors: ci.map(|c| vec![c]),
            }),
        }
    }
    line_plot(
        "RMSE x100 against extra keyframes",
        "K_x (extra keyframes)",
        "RMSE x100",
        &series,
        path,
    )
}

/// A grid mesh with exactly `n` vertices (rows × cols, cols the largest divisor ≤ √n) waving over `frames` frames;
/// the input of the timing table (P-Table 4), in the normalised frame.
pub fn timing_clip(n: usize, frames: usize) -> Result<Clip> {
    let cols = (1..=((n as f64).sqrt() as usize))
        .rev()
        .find(|c| n.is_multiple_of(*c))
        .unwrap_or(1);
    let rows = n / cols;
    if rows < 2 || cols < 2 {
        return Err(DataError::new(
            "timing",
            "vertices",
            format!("{n} vertices do not form a grid of at least 2 × 2"),
        ));
    }
    let mut faces = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let v = (r * cols + c) as u32;
            let (right, down) = (v + 1, v + cols as u32);
            faces.push([v, right, down]);
            faces.push([right, down + 1, down]);
        }
    }
    let vertices = (0..frames)
        .flat_map(|f| {
            (0..n).map(move |i| {
                let (x, y) = (
                    (i % cols) as f32 / (cols - 1) as f32 * 2.0 - 1.0,
                    (i / cols) as f32 / (rows - 1) as f32 * 2.0 - 1.0,
                );
                [x, y, 0.2 * (3.0 * x + 0.3 * f as f32).sin()]
            })
        })
        .collect();
    Clip::new(
        format!("timing_{n}x{frames}"),
        vertices,
        frames,
        n,
        faces,
        "a waving sheet",
        "timing",
    )
}

fn run_timing(opts: &RunOptions) -> Result<TableReport> {
    if opts.methods.is_empty() || opts.timing_reps == 0 {
        return Err(DataError::new(
            "eval run",
            "methods",
            "table4 needs at least one method and one timed repetition",
        ));
    }
    let mut records = Vec::new();
    let total = opts.methods.len() * opts.timing_frames.len() * opts.timing_vertices.len();
    let bar = progress_bar(opts.progress, total, "timing")?;
    for method in &opts.methods {
        for &frames in &opts.timing_frames {
            for &n in &opts.timing_vertices {
                let clip = timing_clip(n, frames)?;
                let keyframes: Vec<usize> = (0..frames)
                    .step_by(15)
                    .chain([frames - 1])
                    .collect::<std::collections::BTreeSet<_>>()
                    .into_iter()
                    .collect();
                let captions = vec![clip.caption.clone()];
                let once = || -> Result<()> {
                    if frames <= 16 {
                        method.complete(
                            &crate::methods::hide_non_keyframes(&clip, &keyframes),
                            &keyframes,
                            &clip.caption,
                            42,
                        )?;
                    } else {
                        long_horizon(method.as_ref(), &clip, &keyframes, &captions, 42, opts.overlap_source)?;
                    }
                    Ok(())
                };
                once()?; // warm-up
                let mut seconds = Vec::with_capacity(opts.timing_reps);
                for _ in 0..opts.timing_reps {
                    let t = Instant::now();
                    once()?;
                    seconds.push(t.elapsed().as_secs_f64());
                }
                records.push(TimingRecord {
                    method: method.kind().label(),
                    frames,
                    vertices: n,
                    seconds,
                });
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    let header = header_for(opts, Path::new("none (synthetic grid meshes)"));
    let (md, csv_text) = timing_tables(&records, &header);
    let mut files = Vec::new();
    write_text(&opts.out.join("summary.md"), &md, &mut files)?;
    write_text(&opts.out.join("summary.csv"), &csv_text, &mut files)?;
    Ok(TableReport {
        kind: TableKind::Table4,
        rows: Vec::new(),
        markdown: md,
        files,
    })
}

fn run_reconstruction(opts: &RunOptions) -> Result<TableReport> {
    if opts.vaes.is_empty() {
        return Err(DataError::new("eval run", "vaes", "table5 needs at least one VAE"));
    }
    let source = StoreSource::open(&opts.data)?;
    let manifest_path = opts.out.join("manifest.json");
    let manifest = match &opts.manifest {
        Some(p) => Manifest::load(p)?,
        None => {
            let mo = ManifestOptions {
                n_clips: opts.clips,
                seeds: vec![0],
                ..ManifestOptions::table1(opts.data.display().to_string())
            };
            Manifest::build(&source.candidates(16), &mo, &opts.data.display().to_string())?
        }
    };
    manifest.save(&manifest_path)?;
    let bar = progress_bar(opts.progress, manifest.clips.len(), "reconstructing")?;
    let mut records = Vec::new();
    for (i, item) in manifest.clips.iter().enumerate() {
        let (gt, _) = source.item(item, manifest.frames)?;
        for vae in &opts.vaes {
            let rec = vae.reconstruct(&gt)?;
            let err = |e: crate::metrics::EvalError| DataError::new(&gt.id, vae.label(), e.to_string());
            let decoded = Motion::new(&rec, gt.frames, gt.n_vertices).map_err(err)?;
            let r = vae_reconstruction(decoded, Motion::from_clip(&gt).map_err(err)?).map_err(err)?; // (E4)
            let metrics = [("rmse".to_string(), r.rmse), ("chamfer".to_string(), r.chamfer)]
                .into_iter()
                .collect();
            records.push(ClipRecord {
                method: vae.label(),
                placement: "all_frames".into(),
                k_extra: 0,
                seed: 0,
                item: i,
                clip_id: item.clip.id.clone(),
                metrics,
            });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let mut files = vec![manifest_path.clone()];
    let parquet = opts.out.join("clips.parquet");
    write_clip_parquet(&records, &parquet)?;
    files.push(parquet);
    let rows = summarize(&records, TableKind::Table5)?;
    let header = header_for(opts, &manifest_path);
    let md = markdown(TableKind::Table5, &rows, &header);
    write_text(&opts.out.join("summary.md"), &md, &mut files)?;
    write_text(
        &opts.out.join("summary.csv"),
        &csv(TableKind::Table5, &rows, &header),
        &mut files,
    )?;
    Ok(TableReport {
        kind: TableKind::Table5,
        rows,
        markdown: md,
        files,
    })
}

/// `any4d eval render`: redraw the pictures of a finished run in `out` from its files: `rmse_vs_kx.png` from
/// `clips.parquet` (random placement, 16 frames), and a strip per exported `predictions/<stem>.bin`, with ground
/// truth and keyframes taken from `manifest.json` and the store `data`. Returns the written paths.
pub fn render_results(out: &Path, data: &Path) -> Result<Vec<PathBuf>> {
    let manifest = Manifest::load(&out.join("manifest.json"))?;
    let mut files = Vec::new();
    if manifest.frames == 16 && matches!(manifest.placement, Placement::Random { .. }) {
        let rows = summarize(&read_clip_parquet(&out.join("clips.parquet"))?, TableKind::Table1)?;
        let path = out.join("rmse_vs_kx.png");
        plot_rmse_vs_kx(&rows, &path)?;
        files.push(path);
    }
    let pred_dir = out.join("predictions");
    if !pred_dir.is_dir() {
        return Ok(files);
    }
    let source = StoreSource::open(data)?;
    let mut bins: Vec<PathBuf> = std::fs::read_dir(&pred_dir)
        .map_err(|e| DataError::io(&pred_dir, e))?
        .map(|e| e.map(|e| e.path()).map_err(|err| DataError::io(&pred_dir, err)))
        .collect::<Result<Vec<_>>>()?;
    bins.retain(|p| p.extension().is_some_and(|e| e == "bin"));
    bins.sort();
    let strips = out.join("strips");
    std::fs::create_dir_all(&strips).map_err(|e| DataError::io(&strips, e))?;
    for bin in bins {
        let stem = bin
            .file_stem()
            .and_then(|s| s.to_str())
            .map(str::to_owned)
            .ok_or_else(|| DataError::new(&bin, "file name", "is not UTF-8"))?;
        let (item, method, k_extra) = parse_stem(&stem)
            .ok_or_else(|| DataError::new(&bin, "file name", "expected item<i>_<method>_k<K_x>_seed<s>.bin"))?;
        let entry = manifest.clips.get(item).ok_or_else(|| {
            DataError::new(
                &bin,
                "item",
                format!("{item} is past the manifest's {} items", manifest.clips.len()),
            )
        })?;
        let keyframes = entry
            .keyframes
            .iter()
            .find(|set| set.len() == k_extra + 2)
            .ok_or_else(|| {
                DataError::new(
                    &bin,
                    "k",
                    format!("the manifest has no set with K_x = {k_extra} for item {item}"),
                )
            })?;
        let (gt, _) = source.item(entry, manifest.frames)?;
        let pred = any4d_data::formats::read_clip(&bin)?;
        let path = strips.join(format!("{stem}.png"));
        let opts = StripOptions {
            prediction_label: method,
            ..StripOptions::default()
        };
        write_strip(&gt, &pred, keyframes, &opts, &path)?;
        files.push(path);
    }
    Ok(files)
}

/// Inverse of [`prediction_stem`]: (item, method, K_x).
fn parse_stem(stem: &str) -> Option<(usize, String, usize)> {
    let (head, _seed) = stem.rsplit_once("_seed")?;
    let (head, k) = head.rsplit_once("_k")?;
    let (item, method) = head.strip_prefix("item")?.split_once('_')?;
    match (item.parse(), k.parse()) {
        (Ok(i), Ok(k)) => Some((i, method.to_string(), k)),
        _ => None, // not a stem this module wrote
    }
}
