//! `any4d eval run` and `any4d eval render`: one command per paper table (docs/method.md §6–§7), learned methods built
//! from run folders by `crate::evaluate`.

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_data::store::Store;
use any4d_eval::methods::MethodKind;
use any4d_eval::protocol::Placement;
use any4d_eval::rollout::OverlapSource;
use any4d_eval::run::{RunOptions, render_results, run_protocol};
use any4d_eval::tables::{TableHeader, TableKind};
use any4d_model::rectified_flow::Solver;
use anyhow::{Context, bail};
use clap::{Args, ValueEnum};

use crate::backend::{self, Backend, Precision};
use crate::evaluate::{LearnedRuns, SamplingSetup, build_methods, build_reconstructors};

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

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OverlapArg {
    /// Ground-truth overlap frame (keyframe methods).
    Gt,
    /// Generated overlap frame (autoregressive).
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
    /// Methods, comma-separated: keyframe_rf, replacement_rf, lerp, lerp_latent, static_nearest,
    /// impute_until_0.98, impute_until_0.98_noisy1.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "keyframe_rf,replacement_rf,lerp,static_nearest"
    )]
    pub methods: Vec<String>,
    /// Keyframe-conditioned RF run (ours; impute-until uses it too).
    #[arg(long)]
    pub rf: Option<PathBuf>,
    /// Non-keyframe RF run (`kf_mode = "none"`), sampled with replacement.
    #[arg(long)]
    pub baseline_rf: Option<PathBuf>,
    /// VAE run (latent lerp; table 5).
    #[arg(long)]
    pub vae: Option<PathBuf>,
    /// Second VAE run for table 5.
    #[arg(long)]
    pub vae_b: Option<PathBuf>,
    /// Clips in the manifest (docs/method.md §6.1: 100).
    #[arg(long, default_value_t = 100)]
    pub clips: usize,
    /// Noise seeds; several give mean ± 95 % CI (docs/method.md §8 X8).
    #[arg(long, value_delimiter = ',', default_value = "42")]
    pub seeds: Vec<u64>,
    /// Keyframe placement of table 1: random, every_<r> or bernoulli_<p> (docs/method.md §8 X4).
    #[arg(long, default_value = "random")]
    pub placement: String,
    /// Reuse a manifest instead of drawing one.
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// Stage-2 reference of table 2 (docs/method.md §7, A8).
    #[arg(long, value_enum, default_value_t = OverlapArg::Gt)]
    pub overlap_source: OverlapArg,
    /// Items whose predictions are exported and drawn as strips.
    #[arg(long, default_value_t = 4)]
    pub export: usize,
    /// ODE grid points (docs/method.md §4.6: 64).
    #[arg(long, default_value_t = 64)]
    pub n_grid: usize,
    /// ODE solver (docs/method.md §4.6: midpoint).
    #[arg(long, value_enum, default_value_t = SolverArg::Midpoint)]
    pub solver: SolverArg,
    /// Classifier-free guidance weight (docs/method.md §9 item 9: 1.0).
    #[arg(long, default_value_t = 1.0)]
    pub guidance: f64,
    /// Table 4: vertex counts timed.
    #[arg(long, value_delimiter = ',', default_value = "512,1024,2048,4096")]
    pub timing_vertices: Vec<usize>,
    /// Table 4: frame counts timed (16 = one window, 31 = the two-stage rollout).
    #[arg(long, value_delimiter = ',', default_value = "16,31")]
    pub timing_frames: Vec<usize>,
    /// Table 4: timed repetitions after one warm-up (median reported).
    #[arg(long, default_value_t = 10)]
    pub timing_reps: usize,
    /// Compute backend.
    #[arg(long, value_enum, default_value_t = Backend::Flex)]
    pub backend: Backend,
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

fn placement(s: &str) -> anyhow::Result<Placement> {
    if s == "random" {
        return Ok(Placement::Random { k_extra_max: 3 });
    }
    if let Some(r) = s.strip_prefix("every_") {
        let r: usize = r
            .parse()
            .with_context(|| format!("--placement {s}: r must be a whole number"))?;
        return Ok(Placement::EveryR { r });
    }
    if let Some(p) = s.strip_prefix("bernoulli_") {
        let p: f32 = p
            .parse()
            .with_context(|| format!("--placement {s}: p must be a number in (0, 1)"))?;
        return Ok(Placement::Bernoulli { p });
    }
    bail!("--placement {s}: expected random, every_<r> or bernoulli_<p>")
}

pub fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let kinds = args
        .methods
        .iter()
        .map(|m| MethodKind::parse(m).map_err(anyhow::Error::from))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let protocol = match args.protocol {
        ProtocolArg::Table1 => TableKind::Table1,
        ProtocolArg::Table2 => TableKind::Table2,
        ProtocolArg::Table4 => TableKind::Table4,
        ProtocolArg::Table5 => TableKind::Table5,
    };
    let device = backend::device(args.backend, Precision::F32)?;
    let tokens = Store::open(&args.data)?.p();
    let runs = LearnedRuns {
        rf: args.rf.clone(),
        baseline_rf: args.baseline_rf.clone(),
        vae: args.vae.clone(),
        vae_b: args.vae_b.clone(),
    };
    let mut opts = RunOptions::new(protocol, args.data.clone(), args.out.clone());
    let checkpoints = if protocol == TableKind::Table5 {
        let (vaes, ckpts) = build_reconstructors(&runs, tokens, &device)?;
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
        };
        let built = build_methods(&kinds, &runs, tokens, sampling, &device)?;
        opts.methods = built.methods;
        built.checkpoints
    };
    opts.clips = args.clips;
    opts.seeds = args.seeds;
    opts.placement = placement(&args.placement)?;
    opts.manifest = args.manifest;
    opts.overlap_source = match args.overlap_source {
        OverlapArg::Gt => OverlapSource::GroundTruth,
        OverlapArg::Generated => OverlapSource::Generated,
    };
    opts.export_items = args.export;
    opts.timing_vertices = args.timing_vertices;
    opts.timing_frames = args.timing_frames;
    opts.timing_reps = args.timing_reps;
    opts.progress = !args.no_progress;
    let uses_rf = kinds.iter().any(|k| k.needs_model());
    opts.header = TableHeader {
        text_encoder: if uses_rf { "scratch".into() } else { "none".into() },
        checkpoints: checkpoints.into_iter().collect(),
        device: if protocol == TableKind::Table5 {
            format!("{:?}", args.backend)
        } else {
            format!(
                "{:?}; sampler {:?} on a {}-point grid, guidance {}",
                args.backend, args.solver, args.n_grid, args.guidance
            )
        },
        ..TableHeader::default()
    };
    let report = run_protocol(&opts)?;
    println!("{}", report.markdown);
    println!("written to {}", args.out.display());
    Ok(ExitCode::SUCCESS)
}

pub fn render(args: RenderArgs) -> anyhow::Result<ExitCode> {
    let files = render_results(&args.out, &args.data)?;
    for f in &files {
        println!("{}", f.display());
    }
    Ok(ExitCode::SUCCESS)
}
