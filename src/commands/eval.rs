//! `any4d eval …` and `any4d bench metrics`: parse arguments, call `any4d_eval` (metrics: docs/method.md §6.1–§6.2;
//! `eval run`: one paper table, its learned methods built from run folders by `any4d_train::evaluate`).

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_data::formats::read_clip;
use any4d_data::keyframes::Placement;
use any4d_eval::bench::{MetricsBench, timed, write_f32_clips};
use any4d_eval::learned::KeyPosterior;
use any4d_eval::methods::MethodKind;
use any4d_eval::metrics::{ClipMetrics, Coordinates, Motion, Scoring, average, evaluate_clip_with};
use any4d_eval::protocol::EvalSplit;
use any4d_eval::rollout::OverlapSource;
use any4d_eval::tables::long_horizon::LongHorizon;
use any4d_eval::tables::reconstruction::Reconstruction;
use any4d_eval::tables::short_horizon::ShortHorizon;
use any4d_eval::tables::summary::TableHeader;
use any4d_eval::tables::timing::{PAPER_REPS, Timing};
use any4d_eval::tables::{CaptionMode, Items, PAPER_CLIPS, Protocol, TableOptions, render_results, run_protocol};
use any4d_model::rectified_flow::{ReplaceNoise, Solver};
use any4d_train::backend::{self, Backend, Precision};
use any4d_train::evaluate::{LearnedRuns, SamplingSetup, build_methods, build_reconstructors};
use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use super::enum_parser;
use crate::reference::{PythonReference, Skipped};

#[derive(Subcommand, Debug)]
pub enum EvalCmd {
    /// Score a predicted clip against its ground truth: RMSE, Chamfer, DTW, jerk, … (docs/method.md §6.2).
    Metrics(MetricsArgs),
    /// Run one paper table's protocol: per-clip parquet, Markdown/CSV summary, strips and plots.
    Run(Box<RunArgs>),
    /// Redraw the strips and the RMSE-vs-K_x plot of an earlier `eval run`.
    Render(RenderArgs),
    /// How a clip sits in a static scene: collision frame and vertex ratios, deepest penetration and foot skating,
    /// (E8)–(E10) (docs/method.md §6.5), both normalised by the clip's frame 0 (D1)–(D3).
    Scene(super::scene::SceneArgs),
}

/// How `eval metrics` prints its result.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// Raw values (not × 100) as one JSON object.
    Json,
    /// A table with distances × 100, as printed in the paper.
    Table,
}

/// Coordinate frame of the metrics.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoordinatesArg {
    /// Normalise both clips by ground-truth frame 0, (D1)–(D3) (docs/method.md §6.1).
    Normalise,
    /// Use the files' coordinates as they are.
    AsGiven,
}

#[derive(Args, Debug)]
pub struct MetricsArgs {
    /// Predicted clip (.bin, .gltf, .glb or a folder of .obj frames).
    pub pred: PathBuf,
    /// Ground-truth clip, same vertex count and frame count.
    pub gt: PathBuf,
    /// Zero-based keyframe indices, comma-separated, e.g. 0,7,15 [default: first and last frame].
    #[arg(long, value_delimiter = ',')]
    pub keyframes: Option<Vec<usize>>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutputFormat::Table)]
    pub format: OutputFormat,
    /// Frame rate r of acceleration and jerk (E5): 1 = per frame, 10 = the 10 FPS renders.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// Coordinate frame of every metric.
    #[arg(long, value_enum, default_value_t = CoordinatesArg::Normalise)]
    pub coordinates: CoordinatesArg,
}

pub fn exec(cmd: EvalCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        EvalCmd::Metrics(args) => metrics(args),
        EvalCmd::Run(args) => run(*args),
        EvalCmd::Render(args) => render(args),
        EvalCmd::Scene(args) => super::scene::scene(args),
    }
}

fn metrics(args: MetricsArgs) -> anyhow::Result<ExitCode> {
    let pred = read_clip(&args.pred).with_context(|| format!("reading the prediction {}", args.pred.display()))?;
    let gt = read_clip(&args.gt).with_context(|| format!("reading the ground truth {}", args.gt.display()))?;
    let keyframes = args
        .keyframes
        .clone()
        .unwrap_or_else(|| vec![0, gt.frames.saturating_sub(1)]);
    let coordinates = match args.coordinates {
        CoordinatesArg::Normalise => Coordinates::NormaliseByGtFrame0,
        CoordinatesArg::AsGiven => Coordinates::AsGiven,
    };
    let scoring = Scoring {
        coordinates,
        rate: args.rate,
    };
    let m = evaluate_clip_with(Motion::from_clip(&pred)?, Motion::from_clip(&gt)?, &keyframes, &scoring)
        .with_context(|| format!("scoring {} against {}", args.pred.display(), args.gt.display()))?;
    match args.format {
        OutputFormat::Json => println!("{}", serde_json::to_string_pretty(&m)?),
        OutputFormat::Table => {
            println!(
                "{} vs {}: {} frames × {} vertices, keyframes {keyframes:?}, r = {}",
                args.pred.display(),
                args.gt.display(),
                gt.frames,
                gt.n_vertices,
                args.rate
            );
            print!("{}", table(&m));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The paper's layout: distances × 100, then the motion diagnostics raw with their ground-truth values.
fn table(m: &ClipMetrics) -> String {
    let mut s = String::new();
    for (name, v) in [
        ("RMSE ×100", m.rmse),
        ("mae_elem ×100", m.mae_elem),
        ("Chamfer ×100", m.chamfer),
        ("DTW ×100", m.dtw),
        ("mean vertex error ×100", m.mean_vertex_error),
        ("keyframe RMSE ×100", m.keyframe_rmse),
    ] {
        s += &format!("{name:<24}{:>12.4}\n", 100.0 * v);
    }
    s += &format!("{:<24}{:>14}{:>14}{:>14}\n", "", "prediction", "GT", "ratio");
    for (name, p, g, r) in [
        ("acceleration", m.accel, m.accel_gt, m.accel_ratio),
        ("jerk", m.jerk, m.jerk_gt, m.jerk_ratio),
        ("motion energy", m.energy, m.energy_gt, m.energy_ratio),
    ] {
        s += &format!("{name:<24}{:>14}{:>14}{:>14}\n", number(p), number(g), number(r));
    }
    s
}

/// Six decimals, or scientific notation for values too small or large for them.
fn number(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:.4e}")
    } else {
        format!("{v:.6}")
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProtocolArg {
    /// P-Table 1: 16 frames, first + last + K_x = 0..3 random keyframes.
    Table1,
    /// P-Table 2: 31 frames, two-stage rollout, keyframes 0, 15, 30.
    Table2,
    /// P-Table 4: end-to-end seconds at 512/1024/2048/4096 vertices and 16/31 frames.
    Table4,
    /// P-Table 5: VAE reconstruction (frame-wise vs sequence-wise).
    Table5,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverArg {
    Euler,
    Midpoint,
}

/// Seed of `--posterior sample` draws (mixed with each clip id and frame).
const POSTERIOR_SEED: u64 = 0x9E37_79B9_7F4A_7C15;

/// `--posterior`: which latent of a keyframe's posterior the learned methods and table 5 use.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PosteriorArg {
    /// The posterior mean μ (the paper).
    Mean,
    /// A posterior sample μ + σξ, ξ seeded by the clip and frame (reproducible).
    Sample,
}

/// `--replace-noise` (docs/method.md §8 X9).
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplaceNoiseArg {
    /// ε_key = the trajectory's initial noise (the paper).
    Fixed,
    /// New noise at every evaluation, seeded from the items' noise seeds.
    Fresh,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OverlapArg {
    /// The ground-truth overlap frame where it is a keyframe (on request; the summary says so).
    Gt,
    /// Each row's own generated overlap frame (autoregressive; every row alike).
    Generated,
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Which paper table.
    #[arg(long, value_enum)]
    pub protocol: ProtocolArg,
    /// Dataset store (`any4d data import` / `data synth`).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder for summary.md/.csv, clips.parquet, manifest.json, strips and plots.
    #[arg(long)]
    pub out: PathBuf,
    /// Methods, comma-separated: keyframe_rf, replacement_rf, lerp, lerp_latent, static_nearest, bdlstm, bdlstm_acap, aam,
    /// impute_until_0.98, impute_until_0.98_noisy1, keyframe_rf_mean8 (mean of 8 samples by ours), vae_oracle (every
    /// ground-truth frame through the VAE: the floor of the latent rows, not a completion method), and a latent
    /// method with `_corrected` after it (keyframe_rf_corrected, keyframe_rf_mean8_corrected, lerp_latent_corrected,
    /// …: its output moved by the keyframes' interpolated decoding residuals, docs/method.md §5.6; not the paper's).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "keyframe_rf,replacement_rf,lerp,static_nearest"
    )]
    pub methods: Vec<String>,
    /// Keyframe-conditioned RF run (ours; impute-until uses it too).
    #[arg(long)]
    pub rf: Option<PathBuf>,
    /// Non-keyframe RF run (`conditioning = "none"`), sampled with replacement.
    #[arg(long)]
    pub baseline_rf: Option<PathBuf>,
    /// VAE run (latent lerp; table 5).
    #[arg(long)]
    pub vae: Option<PathBuf>,
    /// Second VAE run for table 5.
    #[arg(long)]
    pub vae_b: Option<PathBuf>,
    /// BD-LSTM run (`any4d train bdlstm`; method `bdlstm`), completed on the VAE it was trained on.
    #[arg(long)]
    pub bdlstm: Option<PathBuf>,
    /// BD-LSTM run of the ACAP variant (`any4d train bdlstm --variant acap`; method `bdlstm_acap`): only for clips
    /// of the one topology it was trained on.
    #[arg(long)]
    pub bdlstm_acap: Option<PathBuf>,
    /// AnimateAnyMesh reference run (method `aam`): an RF trained on a sequence-wise VAE (`configs/rf/aam_*.toml`),
    /// conditioned on the reference mesh and the caption only, sampled with CFG 3 (its code's weight; --guidance does not
    /// apply to it).
    #[arg(long)]
    pub aam: Option<PathBuf>,
    /// Clips in the manifest (docs/method.md §6.1: 100); a --manifest fixes its own.
    #[arg(long, default_value_t = PAPER_CLIPS, conflicts_with = "manifest")]
    pub clips: usize,
    /// Noise seeds; several give mean ± 95 % CI (docs/method.md §8 X8); a --manifest fixes its own.
    #[arg(long, value_delimiter = ',', default_value = "42", conflicts_with = "manifest")]
    pub seeds: Vec<u64>,
    /// Which clips of the store the items come from: val (the paper's protocol), train, or all (a held-out store
    /// imported from real files, scored whole).
    #[arg(long, default_value = "val", value_parser = EvalSplit::parse)]
    pub split: EvalSplit,

    /// Keyframe placement of table 1: random, every_<r> or bernoulli_<p> (docs/method.md §8 X4); a --manifest fixes
    /// its own.
    #[arg(long, default_value = "random", value_parser = Placement::parse, conflicts_with = "manifest")]
    pub placement: Placement,
    /// Reuse a manifest instead of drawing one: its clips, keyframes and seeds (so --clips, --seeds and --placement
    /// are refused beside it; edit its `seeds` list to run other seeds on the same windows).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// Table 5 only: also write `vertices.parquet`, every vertex's error and features (docs/evaluation.md).
    #[arg(long)]
    pub per_vertex: bool,
    /// Stage-2 reference of table 2 (docs/method.md §7, A8): each row's own generated frame, or the ground truth.
    #[arg(long, value_enum, default_value_t = OverlapArg::Generated)]
    pub overlap_source: OverlapArg,
    /// Items whose predictions are exported and drawn as strips.
    #[arg(long, default_value_t = TableOptions::EXPORT_ITEMS)]
    pub export: usize,
    /// ODE grid points (docs/method.md §4.6: 64).
    #[arg(long, default_value_t = SamplingSetup::default().n_grid)]
    pub n_grid: usize,
    /// ODE solver (docs/method.md §4.6: midpoint).
    #[arg(long, value_enum, default_value_t = SolverArg::Midpoint)]
    pub solver: SolverArg,
    /// Classifier-free guidance weight (docs/method.md §9 item 9: 1.0).
    #[arg(long, default_value_t = 1.0)]
    pub guidance: f64,
    /// Noise that re-noises the Baseline's keyframes (docs/method.md §8 X9).
    #[arg(long, value_enum, default_value_t = ReplaceNoiseArg::Fixed)]
    pub replace_noise: ReplaceNoiseArg,
    /// Scale s of the RF sampler's initial noise, X₀ = s ε (docs/method.md §4.6, §8 X14; 1 in the paper, which every
    /// target is stated for; 0 is deterministic; below 1 it is not a temperature: the early states leave the
    /// training distribution).
    #[arg(long, default_value_t = 1.0)]
    pub noise_scale: f64,
    /// Keyframe latents (and table 5's): the posterior mean (the paper) or a seeded posterior sample, for a VAE
    /// whose decoder never saw μ in some channels (experiments/2026-12-01-small).
    #[arg(long, value_enum, default_value_t = PosteriorArg::Mean)]
    pub posterior: PosteriorArg,
    /// Table 4: vertex counts timed [default: 512,1024,2048,4096].
    #[arg(long, value_delimiter = ',')]
    pub timing_vertices: Option<Vec<usize>>,
    /// Table 4: frame counts timed (16 = one window, 31 = the two-stage rollout) [default: 16,31].
    #[arg(long, value_delimiter = ',')]
    pub timing_frames: Option<Vec<usize>>,
    /// Table 4: timed repetitions after one warm-up (median reported).
    #[arg(long, default_value_t = PAPER_REPS)]
    pub timing_reps: usize,
    /// Compute backend.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), default_value = "flex")]
    pub backend: Backend,
    /// Captions given to the methods: each clip's own (the paper's protocol) or none (every caption empty, the
    /// unconditional input: what the text adds).
    #[arg(long, value_enum, default_value_t = CaptionArg::Clip)]
    pub captions: CaptionArg,
    /// Hide the progress bar.
    #[arg(long)]
    pub no_progress: bool,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Output folder of an earlier `any4d eval run`.
    #[arg(long)]
    pub out: PathBuf,
    /// The dataset store it was run on.
    #[arg(long)]
    pub data: PathBuf,
}

impl RunArgs {
    /// The evaluation items of `--clips`, `--seeds` and `--manifest`.
    fn items(&self) -> Items {
        Items {
            clips: self.clips,
            seeds: self.seeds.clone(),
            manifest: self.manifest.clone(),
        }
    }

    /// The table of `--protocol` with its options.
    fn protocol(&self) -> Protocol {
        let overlap_source = match self.overlap_source {
            OverlapArg::Gt => OverlapSource::GroundTruth,
            OverlapArg::Generated => OverlapSource::Generated,
        };
        match self.protocol {
            ProtocolArg::Table1 => Protocol::ShortHorizon(ShortHorizon {
                items: self.items(),
                placement: self.placement,
            }),
            ProtocolArg::Table2 => Protocol::LongHorizon(LongHorizon {
                items: self.items(),
                overlap_source,
            }),
            ProtocolArg::Table4 => {
                let paper = Timing::default();
                Protocol::Timing(Timing {
                    vertices: self.timing_vertices.clone().unwrap_or(paper.vertices),
                    frames: self.timing_frames.clone().unwrap_or(paper.frames),
                    reps: self.timing_reps,
                    overlap_source,
                })
            }
            ProtocolArg::Table5 => Protocol::Reconstruction(Reconstruction {
                clips: self.clips,
                manifest: self.manifest.clone(),
                per_vertex: self.per_vertex,
            }),
        }
    }
}

/// `any4d eval run`: the learned methods (or VAEs) from their run folders, then the table.
fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let kinds = args
        .methods
        .iter()
        .map(|m| MethodKind::parse(m).map_err(anyhow::Error::from))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let table5 = matches!(args.protocol, ProtocolArg::Table5);
    anyhow::ensure!(table5 || !args.per_vertex, "--per-vertex: table 5 only");
    let protocol = args.protocol();
    let device = backend::device(args.backend, Precision::F32)?;
    let runs = LearnedRuns {
        rf: args.rf.clone(),
        baseline_rf: args.baseline_rf.clone(),
        vae: args.vae.clone(),
        vae_b: args.vae_b.clone(),
        bdlstm: args.bdlstm.clone(),
        bdlstm_acap: args.bdlstm_acap.clone(),
        aam: args.aam.clone(),
    };
    let mut opts = TableOptions::new(args.data.clone(), args.out.clone());
    let posterior = match args.posterior {
        PosteriorArg::Mean => KeyPosterior::Mean,
        PosteriorArg::Sample => KeyPosterior::Sample { seed: POSTERIOR_SEED },
    };
    let reconstruction = matches!(protocol, Protocol::Reconstruction(_));
    let checkpoints = if reconstruction {
        let (vaes, ckpts) = build_reconstructors(&runs, posterior, &device)?;
        opts.vaes = vaes;
        ckpts
    } else {
        let sampling = SamplingSetup {
            n_grid: args.n_grid,
            solver: match args.solver {
                SolverArg::Euler => Solver::Euler,
                SolverArg::Midpoint => Solver::Midpoint,
            },
            guidance: args.guidance,
            replace_noise: match args.replace_noise {
                ReplaceNoiseArg::Fixed => ReplaceNoise::Fixed,
                ReplaceNoiseArg::Fresh => ReplaceNoise::Fresh,
            },
            posterior,
            noise_scale: args.noise_scale,
        };
        let built = build_methods(&kinds, &runs, sampling, &device)?;
        opts.methods = built.methods;
        built.checkpoints
    };
    opts.export_items = args.export;
    opts.progress = !args.no_progress;
    opts.split = args.split;
    opts.captions = match args.captions {
        CaptionArg::Clip => CaptionMode::Clip,
        CaptionArg::None => CaptionMode::Empty,
    };
    let uses_rf = kinds.iter().any(|k| k.needs_model());
    opts.header = TableHeader {
        text_encoder: if uses_rf { "scratch".into() } else { "none".into() },
        checkpoints: checkpoints.into_iter().collect(),
        device: if reconstruction {
            format!("{:?}", args.backend)
        } else {
            format!(
                "{:?}; sampler {:?} on a {}-point grid, guidance {}{}, keyframe latents: posterior {:?}{}",
                args.backend,
                args.solver,
                args.n_grid,
                args.guidance,
                if kinds.contains(&MethodKind::Aam) {
                    format!(" (aam: {})", any4d_eval::methods::AAM_GUIDANCE)
                } else {
                    String::new()
                },
                args.posterior,
                if args.noise_scale == 1.0 {
                    String::new()
                } else {
                    format!(", initial noise × {}", args.noise_scale)
                }
            )
        },
        ..TableHeader::default()
    };
    let report = run_protocol(&protocol, &opts)?;
    println!("{}", report.markdown);
    println!("written to {}", args.out.display());
    Ok(ExitCode::SUCCESS)
}

/// `any4d eval render`.
fn render(args: RenderArgs) -> anyhow::Result<ExitCode> {
    let files = render_results(&args.out, &args.data)?;
    for f in &files {
        println!("{}", f.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// `eval run --captions`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum CaptionArg {
    /// Each clip's caption.
    Clip,
    /// No caption for any clip.
    None,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Number of synthetic clips.
    #[arg(long, default_value_t = 8)]
    pub clips: usize,
    /// Vertices per clip.
    #[arg(long, default_value_t = 4096)]
    pub vertices: usize,
    /// Frames per clip (≥ 4).
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Timed repetitions; the median is reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// The numpy/scipy reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/metrics_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

/// What the reference prints: its median seconds and its per-clip metrics.
#[derive(serde::Deserialize)]
struct Reference {
    seconds: f64,
    metrics: Vec<ClipMetrics>,
}

/// `any4d bench metrics`: [`MetricsBench`] on one thread and on the whole pool, beside the numpy/scipy reference.
pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    let bench = MetricsBench {
        clips: args.clips,
        vertices: args.vertices,
        frames: args.frames,
    };
    bench.check()?;
    let clips = bench.clips();
    let threads = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (t1, ours) = one.install(|| timed(args.repeat, || bench.score(&clips)))?;
    let (tn, _) = timed(args.repeat, || bench.score(&clips))?;
    println!(
        "metrics bench: {} clips × {} frames × {} vertices, keyframes {:?}, median of {} runs",
        args.clips,
        args.frames,
        args.vertices,
        bench.keyframes(),
        args.repeat
    );
    let rate = |secs: f64| args.clips as f64 / secs;
    println!("ours, 1 thread          {:>10.2} clips/s", rate(t1));
    println!("ours, {threads:>2} threads        {:>10.2} clips/s", rate(tn));
    let file = tempfile::NamedTempFile::new().context("creating the clip file of the reference")?;
    write_f32_clips(file.path(), &clips)?;
    let keys = bench
        .keyframes()
        .iter()
        .map(|k| k.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let reference = PythonReference {
        python: &args.python,
        script: &args.script,
        args: [
            "--bench",
            &file.path().display().to_string(),
            "--clips",
            &args.clips.to_string(),
            "--frames",
            &args.frames.to_string(),
            "--vertices",
            &args.vertices.to_string(),
            "--keyframes",
            &keys,
            "--repeat",
            &args.repeat.to_string(),
        ]
        .map(String::from)
        .to_vec(),
        threads: 1,
    };
    match reference.json::<Reference>()? {
        Ok(theirs) => {
            let tr = theirs.seconds;
            println!("numpy+scipy, 1 core     {:>10.2} clips/s", rate(tr));
            println!(
                "speed-up over the reference: {:.2}× (1 thread), {:.2}× ({threads} threads)",
                tr / t1,
                tr / tn
            );
            let (a, b) = (
                serde_json::to_value(ours)?,
                serde_json::to_value(average(&theirs.metrics)?)?,
            );
            let worst = b
                .as_object()
                .context("reference metrics are not an object")?
                .iter()
                .map(|(k, v)| {
                    let (x, y) = (a[k].as_f64().unwrap_or(f64::NAN), v.as_f64().unwrap_or(f64::NAN));
                    ((x - y).abs() / y.abs().max(1e-12), k.clone())
                })
                .max_by(|p, q| p.0.total_cmp(&q.0))
                .context("no metrics to compare")?;
            println!(
                "agreement: largest relative difference of the mean metrics {:.1e} ({})",
                worst.0, worst.1
            );
        }
        Err(Skipped(why)) => println!("reference skipped: {why}"),
    }
    if cfg!(debug_assertions) {
        println!(
            "note: dev-profile binary (the workspace builds any4d-eval at opt-level 2 there); \
             `cargo run --release -- bench metrics` gives release numbers"
        );
    }
    Ok(ExitCode::SUCCESS)
}
