//! The paper tables any4d reproduces (docs/method.md §6–§7), one file per table: [`short_horizon`] (P-Table 1),
//! [`long_horizon`] (P-Table 2), [`timing`] (P-Table 4), [`reconstruction`] (P-Table 5); [`Protocol`] picks one
//! with its options, [`run_protocol`] runs it (`any4d eval run`), [`render_results`] redraws its pictures
//! (`any4d eval render`); [`summary`] holds what every table shares (records, parquet, Markdown, CSV).
//!
//! Methods arrive already built ([`Method`] trait objects): training-free ones come from
//! [`crate::methods::vertex_methods`], the RF methods are built by the caller from its checkpoints (only `train`
//! reads run folders).

use std::path::{Path, PathBuf};

use any4d_data::Clip;
use any4d_data::io::write_atomic;
use any4d_data::keyframes::Placement;
use any4d_data::scene::Scene;
use indicatif::{ProgressBar, ProgressStyle};

use crate::methods::{Method, complete_and_score_batch, metrics_map};
use crate::plot::{Series, line_plot};
use crate::protocol::{EvalSplit, MANIFEST_SEED, Manifest, ManifestOptions, StoreSource, noise_seed};
use crate::render::{ExportFormat, StripOptions, export_sequence, write_strip};
use crate::rollout::{OverlapSource, RolloutSpec};
use crate::view;

pub mod long_horizon;
pub mod reconstruction;
pub mod short_horizon;
pub mod summary;
pub mod timing;
pub mod vertex_errors;

use long_horizon::{LongHorizon, Scored, long_horizon};
use reconstruction::{Reconstruction, Reconstructor};
use short_horizon::ShortHorizon;
use summary::{
    ClipRecord, Layout, SummaryRow, TableHeader, csv, markdown, read_clip_parquet, summarize, write_clip_parquet,
};
use timing::Timing;

use crate::error::{EvalError, Result};

/// Which paper table to reproduce, with the options that belong to it (each `Default` is the paper's protocol).
#[derive(Debug, Clone, PartialEq)]
pub enum Protocol {
    /// P-Table 1: 16 frames, first + last + K_x = 0..3 keyframes.
    ShortHorizon(ShortHorizon),
    /// P-Table 2: 31 frames, two-stage rollout, keyframes 0, 15, 30.
    LongHorizon(LongHorizon),
    /// P-Table 4: end-to-end seconds per vertex count and frame count.
    Timing(Timing),
    /// P-Table 5: VAE reconstruction.
    Reconstruction(Reconstruction),
}

impl Protocol {
    /// The table's layout (title, columns).
    pub fn layout(&self) -> &'static Layout {
        match self {
            Protocol::ShortHorizon(_) => &short_horizon::LAYOUT,
            Protocol::LongHorizon(_) => &long_horizon::LAYOUT,
            Protocol::Timing(_) => &timing::LAYOUT,
            Protocol::Reconstruction(_) => &reconstruction::LAYOUT,
        }
    }
}

/// Which evaluation items a completion table scores: drawn from the store's validation split (how many, with which
/// noise seeds), or read from a saved manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct Items {
    /// Items in a drawn manifest ([`PAPER_CLIPS`]).
    pub clips: usize,
    /// Base noise seeds (`[42]`; docs/method.md §8 X8: 42..=46).
    pub seeds: Vec<u64>,
    /// Reuse this manifest instead of drawing one (it is copied next to the results).
    pub manifest: Option<PathBuf>,
}

/// Evaluation items of the paper's tables (docs/method.md §6.1).
pub const PAPER_CLIPS: usize = 100;

impl Default for Items {
    fn default() -> Self {
        Self {
            clips: PAPER_CLIPS,
            seeds: vec![MANIFEST_SEED],
            manifest: None,
        }
    }
}

/// What every table run shares: the data, the output folder, the methods (or VAEs) and the report settings.
pub struct TableOptions {
    /// Dataset store folder.
    pub data: PathBuf,
    /// Output folder (created; existing result files in it are replaced).
    pub out: PathBuf,
    /// Methods to compare (tables 1, 2, 4), in table order.
    pub methods: Vec<Box<dyn Method>>,
    /// VAEs to compare (table 5).
    pub vaes: Vec<Box<dyn Reconstructor>>,
    /// Predictions of the first `export_items` items are saved and drawn as PNG strips (tables 1, 2).
    pub export_items: usize,
    /// Names method checkpoints, text encoder and device in the table header (data and manifest are filled in).
    pub header: TableHeader,
    /// Show a progress bar over clips on stderr.
    pub progress: bool,
    /// The store's clips the items are drawn from (validation by default).
    pub split: EvalSplit,
    /// The captions the methods are given: each clip's own, or none (the caption ablation).
    pub captions: CaptionMode,
}

/// Which caption a method gets with each clip (`eval run --captions`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CaptionMode {
    /// The clip's caption (the paper's protocol).
    #[default]
    Clip,
    /// The empty caption for every clip: the unconditional input, to measure what the text adds.
    Empty,
}

impl TableOptions {
    /// Options for the store `data`, writing to `out`, with no methods yet, exporting [`Self::EXPORT_ITEMS`] items.
    pub fn new(data: PathBuf, out: PathBuf) -> Self {
        Self {
            data,
            out,
            methods: Vec::new(),
            vaes: Vec::new(),
            export_items: Self::EXPORT_ITEMS,
            header: TableHeader::default(),
            progress: true,
            split: EvalSplit::Val,
            captions: CaptionMode::Clip,
        }
    }

    /// Items whose predictions are exported by default.
    pub const EXPORT_ITEMS: usize = 4;
}

/// What a protocol run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct TableReport {
    /// The table's title.
    pub title: &'static str,
    /// Summary rows (empty for table 4, whose rows are timings).
    pub rows: Vec<SummaryRow>,
    /// The Markdown summary (also written to `summary.md`).
    pub markdown: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// `any4d eval run`: the table of `protocol` over `opts`, written to `opts.out`.
pub fn run_protocol(protocol: &Protocol, opts: &TableOptions) -> Result<TableReport> {
    std::fs::create_dir_all(&opts.out).map_err(|e| EvalError::io(&opts.out, e))?;
    match protocol {
        Protocol::ShortHorizon(p) => p.run(opts),
        Protocol::LongHorizon(p) => p.run(opts),
        Protocol::Timing(p) => p.run(opts),
        Protocol::Reconstruction(p) => p.run(opts),
    }
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

pub(crate) fn progress_bar(show: bool, len: usize, what: &str) -> Result<ProgressBar> {
    if !show {
        return Ok(ProgressBar::hidden());
    }
    let style = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} clips, {per_sec}, ETA {eta}")
        .map_err(|e| EvalError::invalid("progress bar", "template", e.to_string()))?;
    let bar = ProgressBar::new(len as u64);
    bar.set_style(style.progress_chars("=> "));
    bar.set_message(what.to_string());
    Ok(bar)
}

/// The `vae_oracle` row reads every ground-truth frame, which only the short-horizon scorer hands it
/// ([`crate::methods::complete_and_score_batch`]); anywhere else it would decode hidden frames and print a row that is
/// no floor, so it is refused there.
pub(crate) fn refuse_oracle(methods: &[Box<dyn Method>], where_: &str) -> Result<()> {
    if methods
        .iter()
        .any(|m| m.kind() == crate::methods::MethodKind::VaeOracle)
    {
        return Err(EvalError::invalid(
            "eval run",
            "vae_oracle",
            format!("runs only on a short-horizon table 1 manifest, not on {where_}"),
        ));
    }
    Ok(())
}

/// Run the methods over a manifest (tables 1 and 2) and return per-clip records and the kept predictions.
pub fn evaluate(
    source: &StoreSource,
    manifest: &Manifest,
    methods: &[Box<dyn Method>],
    overlap_source: OverlapSource,
    keep_items: usize,
    show_progress: bool,
    caption_mode: CaptionMode,
) -> Result<(Vec<ClipRecord>, Vec<Prediction>)> {
    if manifest.frames > RolloutSpec::paper().window {
        refuse_oracle(
            methods,
            "a long-horizon manifest (the rollout shows each window only its keyframes)",
        )?;
    }
    let bar = progress_bar(show_progress, manifest.clips.len(), "evaluating")?;
    let mut records = Vec::new();
    let mut kept = Vec::new();
    let scenes = source.has_scenes();
    for (i, item) in manifest.clips.iter().enumerate() {
        let (gt, mut captions) = source.item(item, manifest.frames)?;
        let scene = if scenes { source.item_scene(item)? } else { None };
        if caption_mode == CaptionMode::Empty {
            captions.iter_mut().for_each(String::clear);
        }
        // Every (keyframe set, seed) of the clip, in this order; one batched call per method on a short horizon.
        let asks: Vec<(&[usize], u64, u64)> = item
            .keyframes
            .iter()
            .flat_map(|k| {
                manifest
                    .seeds
                    .iter()
                    .map(move |&base| (k.as_slice(), base, noise_seed(base, i)))
            })
            .collect();
        for method in methods {
            let label = method.kind().label();
            let scored: Vec<Scored> = if manifest.frames <= RolloutSpec::paper().window {
                let pairs: Vec<(&[usize], u64)> = asks.iter().map(|&(k, _, seed)| (k, seed)).collect();
                complete_and_score_batch(method.as_ref(), &gt, &pairs, &captions[0], scene.as_ref())?
                    .into_iter()
                    .map(|s| (s.prediction, metrics_map(&s.metrics)))
                    .collect()
            } else {
                asks.iter()
                    .map(|&(k, _, seed)| long_horizon(method.as_ref(), &gt, k, &captions, seed, overlap_source))
                    .collect::<Result<_>>()?
            };
            for (&(keyframes, base, _), (prediction, mut metrics)) in asks.iter().zip(scored) {
                if scenes {
                    metrics.extend(short_horizon::scene_columns(scene.as_ref(), &prediction, &gt)?);
                }
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
                        method: label.clone(),
                        keyframes: keyframes.to_vec(),
                        seed: base,
                        vertices: prediction,
                    });
                }
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok((records, kept))
}

pub(crate) fn header_for(opts: &TableOptions, manifest_path: &Path) -> TableHeader {
    let mut h = opts.header.clone();
    if h.data.is_empty() {
        h.data = format!("{} ({} split)", opts.data.display(), opts.split.name());
    }
    h.manifest = manifest_path.display().to_string();
    if h.text_encoder.is_empty() {
        h.text_encoder = "none (no method reads text)".into();
    }
    if opts.captions == CaptionMode::Empty {
        h.text_encoder
            .push_str("; every caption withheld (empty: the unconditional input)");
    }
    for m in &opts.methods {
        h.checkpoints.entry(m.kind().label()).or_insert_with(|| "none".into());
    }
    h
}

pub(crate) fn write_text(path: &Path, text: &str, files: &mut Vec<PathBuf>) -> Result<()> {
    write_atomic(path, text.as_bytes())?;
    files.push(path.to_path_buf());
    Ok(())
}

/// Tables 1 and 2: load the manifest of `items` or draw one with `draw` (its clip count and seeds from `items`), run
/// every method over it (long items through the two-stage rollout with `overlap`, which the summary then names), and
/// write the manifest, per-clip parquet, summaries, the RMSE-vs-K_x plot when `plot`, and the predictions and strips
/// of the first items.
pub(crate) fn run_completion(
    opts: &TableOptions,
    layout: &Layout,
    items: &Items,
    draw: ManifestOptions,
    overlap: Option<OverlapSource>,
    plot: bool,
) -> Result<TableReport> {
    if opts.methods.is_empty() {
        return Err(EvalError::invalid("eval run", "methods", "no methods to evaluate"));
    }
    let source = StoreSource::open(&opts.data, opts.split)?;
    let manifest_path = opts.out.join("manifest.json");
    let manifest = match &items.manifest {
        Some(path) => Manifest::load(path)?,
        None => {
            let draw = ManifestOptions {
                n_clips: items.clips,
                seeds: items.seeds.clone(),
                split: opts.split.name().into(),
                ..draw
            };
            Manifest::build(&source.candidates(draw.frames), &draw, &opts.data.display().to_string())?
        }
    };
    let mut files = Vec::new();
    manifest.save(&manifest_path)?;
    files.push(manifest_path.clone());
    let (records, kept) = evaluate(
        &source,
        &manifest,
        &opts.methods,
        overlap.unwrap_or_default(),
        opts.export_items,
        opts.progress,
        opts.captions,
    )?;
    let parquet = opts.out.join("clips.parquet");
    write_clip_parquet(&records, &parquet)?;
    files.push(parquet);
    let rows = summarize(&records, layout)?;
    let mut header = header_for(opts, &manifest_path);
    header.notes.extend(overlap.map(|o| o.describe().to_string()));
    let md = markdown(layout, &rows, &header);
    write_text(&opts.out.join("summary.md"), &md, &mut files)?;
    write_text(&opts.out.join("summary.csv"), &csv(layout, &rows, &header), &mut files)?;
    if plot && matches!(manifest.placement, Placement::Random { .. }) {
        let path = opts.out.join("rmse_vs_kx.png");
        plot_rmse_vs_kx(&rows, &path)?;
        files.push(path);
    }
    for item in 0..opts.export_items.min(manifest.clips.len()) {
        let (gt, _) = source.item(&manifest.clips[item], manifest.frames)?;
        let preds: Vec<&Prediction> = kept.iter().filter(|p| p.item == item).collect();
        let scene = match source.has_scenes() {
            true => source.item_scene(&manifest.clips[item])?,
            false => None,
        };
        files.extend(write_item_outputs(&gt, scene.as_ref(), &preds, &opts.out)?);
    }
    Ok(TableReport {
        title: layout.title,
        rows,
        markdown: md,
        files,
    })
}

/// PNG strips (`strips/`) and exported sequences (`predictions/`: `.bin`, OBJ folder, `.glb`) of one item, one per
/// (method, keyframe set, seed), and its viewer pages, drawn in the item's `scene` when it has one. File stems:
/// `item<i>_<method>_k<K_x>_seed<s>`.
fn write_item_outputs(gt: &Clip, scene: Option<&Scene>, preds: &[&Prediction], out: &Path) -> Result<Vec<PathBuf>> {
    let strips = out.join("strips");
    std::fs::create_dir_all(&strips).map_err(|e| EvalError::io(&strips, e))?;
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
    files.extend(write_item_views(gt, scene, preds, out)?);
    Ok(files)
}

/// One viewer page (`view/item<i>_k<K_x>_seed<s>.html`) per keyframe set and seed of an item: the ground truth and
/// every method's prediction side by side, coloured by their distance to it, with their scores, in the item's scene.
fn write_item_views(gt: &Clip, scene: Option<&Scene>, preds: &[&Prediction], out: &Path) -> Result<Vec<PathBuf>> {
    let mut groups: Vec<(&[usize], u64, Vec<&Prediction>)> = Vec::new();
    for p in preds {
        match groups
            .iter_mut()
            .find(|(k, s, _)| *k == p.keyframes.as_slice() && *s == p.seed)
        {
            Some(g) => g.2.push(p),
            None => groups.push((p.keyframes.as_slice(), p.seed, vec![p])),
        }
    }
    let mut files = Vec::new();
    for (keyframes, seed, group) in groups {
        let mut panels = vec![view::Panel {
            label: "ground truth".into(),
            clip: gt.clone(),
            metrics: Vec::new(),
        }];
        for p in &group {
            let clip = Clip {
                vertices: p.vertices.clone(),
                ..gt.clone()
            };
            let scored = crate::metrics::Motion::from_clip(&clip).and_then(|pred| {
                crate::metrics::evaluate_clip(pred, crate::metrics::Motion::from_clip(gt)?, keyframes)
            });
            let m = scored.map_err(|e| EvalError::invalid(&gt.id, "view metrics", e.to_string()))?;
            panels.push(view::Panel {
                label: p.method.clone(),
                clip,
                metrics: view::metric_lines(&m),
            });
        }
        let k_extra = keyframes.len().saturating_sub(2);
        let item = group[0].item;
        let page = view::Page {
            title: format!("{} — item {item}, K_x = {k_extra}, seed {seed}", gt.id),
            caption: gt.caption.clone(),
            keyframes: keyframes.to_vec(),
            ground_truth: true,
            panels,
            fps: view::DEFAULT_FPS,
            scene: scene.cloned(),
        };
        let path = out
            .join("view")
            .join(format!("item{item:03}_k{k_extra}_seed{seed}.html"));
        view::write_page(&page, &path)?;
        files.push(path);
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

/// `any4d eval render`: redraw the pictures of a finished run in `out` from its files: `rmse_vs_kx.png` from
/// `clips.parquet` (random placement, 16 frames), and a strip per exported `predictions/<stem>.bin`, with ground
/// truth and keyframes taken from `manifest.json` and the store `data`. Returns the written paths.
pub fn render_results(out: &Path, data: &Path) -> Result<Vec<PathBuf>> {
    let manifest = Manifest::load(&out.join("manifest.json"))?;
    let mut files = Vec::new();
    if manifest.frames == 16 && matches!(manifest.placement, Placement::Random { .. }) {
        let rows = summarize(&read_clip_parquet(&out.join("clips.parquet"))?, &short_horizon::LAYOUT)?;
        let path = out.join("rmse_vs_kx.png");
        plot_rmse_vs_kx(&rows, &path)?;
        files.push(path);
    }
    let pred_dir = out.join("predictions");
    if !pred_dir.is_dir() {
        return Ok(files);
    }
    let source = StoreSource::open(data, EvalSplit::All)?;
    let mut bins: Vec<PathBuf> = std::fs::read_dir(&pred_dir)
        .map_err(|e| EvalError::io(&pred_dir, e))?
        .map(|e| e.map(|e| e.path()).map_err(|err| EvalError::io(&pred_dir, err)))
        .collect::<Result<Vec<_>>>()?;
    bins.retain(|p| p.extension().is_some_and(|e| e == "bin"));
    bins.sort();
    let strips = out.join("strips");
    std::fs::create_dir_all(&strips).map_err(|e| EvalError::io(&strips, e))?;
    for bin in bins {
        let stem = bin
            .file_stem()
            .and_then(|s| s.to_str())
            .map(str::to_owned)
            .ok_or_else(|| EvalError::invalid(&bin, "file name", "is not UTF-8"))?;
        let (item, method, k_extra) = parse_stem(&stem)
            .ok_or_else(|| EvalError::invalid(&bin, "file name", "expected item<i>_<method>_k<K_x>_seed<s>.bin"))?;
        let entry = manifest.clips.get(item).ok_or_else(|| {
            EvalError::invalid(
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
                EvalError::invalid(
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
