//! `any4d train vae|rf|bdlstm` and `any4d bench train`: parse arguments, load the config (`extends`, `--set`), call
//! `any4d_train` (`vae_loop`, `rf_loop`, `bench`). Ctrl-C saves a checkpoint and exits.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use any4d_data::store::DEFAULT_P;
use any4d_model::bench::median;
use any4d_train::backend::{self, Backend, Precision};
use any4d_train::bdlstm::{resume_bdlstm, train_bdlstm};
use any4d_train::bdlstm_loop::{BdlstmRunConfig, BdlstmRunOptions, BdlstmVariant};
use any4d_train::bench::{RfShape, TrainThroughput, rf_step_flops, time_bdlstm_steps, time_rf_steps, time_vae_steps};
use any4d_train::config::{DeviceConfig, Override, TrainConfig};
use any4d_train::devices::{Parallel, Strategy};
use any4d_train::loop_common::{Outcome, RunOptions};
use any4d_train::progress::ProgressMode;
use any4d_train::rf_loop::{
    FileState, RfRunConfig, RfRunOptions, encode_store_latents, resume_rf, shard_file, train_rf,
};
use any4d_train::run_config::RunConfig;
use any4d_train::run_folder::RunFolder;
use any4d_train::vae_loop::{VaeRunConfig, resume_vae, train_vae};
use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use super::{enum_parser, stop_on_ctrl_c};

#[derive(Subcommand, Debug)]
pub enum TrainCmd {
    /// Train the mesh VAE (docs/method.md §3): `--config configs/vae/<preset>.toml --data STORE`.
    Vae(VaeArgs),
    /// Train the keyframe rectified flow on a frozen VAE (docs/method.md §4).
    Rf(RfArgs),
    /// Encode a store's clips with a frozen VAE into the RF's latent files (`rf.latent_cache = "disk"`), one file
    /// per shard: `--vae RUN --data STORE --latents DIR`, or one shard per process with `--shard K`. Files already
    /// current are kept; `train rf --latents DIR` reads them.
    Latents(LatentsArgs),
    /// Train the BD-LSTM baseline (docs/method.md §5.3): the latent adaptation on a frozen VAE
    /// (`--config configs/bdlstm/<preset>.toml --vae RUN --data STORE`), or the original on ACAP features of a
    /// single-topology store (`--variant acap --config configs/bdlstm/<preset>.toml --data STORE`).
    Bdlstm(BdlstmArgs),
}

#[derive(Args, Debug)]
pub struct VaeArgs {
    #[command(flatten)]
    common: RunArgs,
}

#[derive(Args, Debug)]
pub struct RfArgs {
    /// The VAE run folder whose newest checkpoint encodes the clips (with `--resume` or `--init`: optional, must
    /// be that run's own).
    #[arg(long, required_unless_present_any = ["resume", "init"])]
    vae: Option<PathBuf>,
    /// Start the new run from the newest checkpoint of this RF run or packed folder (fine-tuning): its trained
    /// parameters, caption tokenizer and VAE; `--config` must give the same `[model]` and `[text]`. The optimiser,
    /// step count, learning-rate schedule, random streams and parameter average start afresh under `--config`.
    #[arg(long, conflicts_with = "resume")]
    init: Option<PathBuf>,
    /// Folder of the latent files with `rf.latent_cache = "disk"` (made by `any4d train latents`, or here: shards
    /// whose file is missing or stale are encoded into it). Default: `latents/` in the run folder.
    #[arg(long)]
    latents: Option<PathBuf>,
    #[command(flatten)]
    common: RunArgs,
}

#[derive(Args, Debug)]
pub struct LatentsArgs {
    /// The VAE run folder whose newest checkpoint encodes the clips.
    #[arg(long)]
    vae: PathBuf,
    /// Dataset store folder or URL.
    #[arg(long)]
    data: PathBuf,
    /// Folder of the latent files (`shard-KKKKK.latents`).
    #[arg(long)]
    latents: PathBuf,
    /// Encode only shard K (0-based, in the store's manifest order), so that shards run as separate processes.
    #[arg(long)]
    shard: Option<usize>,
    /// Clips per VAE forward.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u64).range(1..=4096))]
    micro_batch: u64,
    /// Backend of the encoding.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), default_value = "flex")]
    backend: Backend,
}

#[derive(Args, Debug)]
pub struct BdlstmArgs {
    /// The frozen VAE run folder of the latent variant (with `--resume`: optional, must be the run's own); the
    /// ACAP variant takes none.
    #[arg(long)]
    vae: Option<PathBuf>,
    /// Frame representation, overriding the config's `model.variant`: `latent` (VAE trajectory latents) or `acap`
    /// (per-vertex ACAP features with mesh convolutions; one fixed topology). A resumed run keeps its own.
    #[arg(long, value_parser = ["latent", "acap"], conflicts_with = "resume")]
    variant: Option<String>,
    #[command(flatten)]
    common: RunArgs,
}

/// `--config` with its `--set` overrides: what every command that reads a run config takes.
#[derive(Args, Debug)]
pub struct ConfigArgs {
    /// Override one key of the config after its `extends` chain: `--set rf.k_max=3`, `--set model.conditioning=none`
    /// (the value is TOML; a bare word is a string). Repeatable; an unknown key is an error.
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE", value_parser = parse_override)]
    pub set: Vec<Override>,
}

fn parse_override(text: &str) -> Result<Override, String> {
    text.parse()
}

/// The options `train vae` and `train rf` share.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Run config (`configs/vae/*.toml` or `configs/rf/*.toml`); not with `--resume`, which reads the run's own
    /// config.
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    config: Option<PathBuf>,
    #[command(flatten)]
    overrides: ConfigArgs,
    /// Dataset store folder (`any4d data import|synth`).
    #[arg(long)]
    data: PathBuf,
    /// Run name: the run goes to `<runs>/<NAME>-<n>/` with the next free n (default: `vae` or `rf`).
    #[arg(long)]
    run: Option<String>,
    /// Continue this run folder from its newest checkpoint.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Override `[device] backend`.
    #[arg(long, value_parser = enum_parser(&Backend::ALL))]
    backend: Option<Backend>,
    /// Train data-parallel over these devices, comma-separated `BACKEND[:INDEX]` (`cuda:0,cuda:1`,
    /// `flex,flex`); the first holds the model and the optimiser. Replaces `[device] backend`. Without it a CPU
    /// backend starts one worker per core, up to the step's micro-batches (the same numbers as one device);
    /// `--devices flex` trains on one.
    #[arg(long, conflicts_with = "backend")]
    devices: Option<String>,
    /// How the devices combine gradients: `ddp` (burn's all-reduce, NCCL; cuda only), `main-device` (gradients
    /// copied to the first device), `auto` (ddp on distinct cuda devices, main-device otherwise).
    #[arg(long, value_parser = enum_parser(&Strategy::ALL), default_value = "auto", requires = "devices")]
    strategy: Strategy,
    /// Folder of run folders.
    #[arg(long, default_value = "runs")]
    runs_dir: PathBuf,
}

impl RunArgs {
    /// `--config` (clap requires it without `--resume`).
    fn config(&self) -> anyhow::Result<&Path> {
        self.config.as_deref().context("give --config or --resume")
    }

    /// The run options: `--data`, `--runs-dir`, `--run` (default `name`), `--devices` with `--strategy` (checked),
    /// progress on the terminal and a Ctrl-C stop flag.
    fn options(&self, name: &str) -> anyhow::Result<RunOptions> {
        if self.resume.is_some() && !self.overrides.set.is_empty() {
            bail!("--set changes a config; a resumed run keeps its own (start a new run instead)");
        }
        let parallel = self
            .devices
            .as_deref()
            .map(|d| Parallel::parse(d, self.strategy))
            .transpose()?;
        Ok(RunOptions {
            data: self.data.clone(),
            runs_dir: self.runs_dir.clone(),
            name: self.run.clone().unwrap_or_else(|| name.into()),
            progress: ProgressMode::Auto,
            stop: stop_on_ctrl_c()?,
            parallel,
        })
    }
}

pub fn exec(cmd: TrainCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        TrainCmd::Vae(args) => vae(args),
        TrainCmd::Rf(args) => rf(args),
        TrainCmd::Latents(args) => latents(args),
        TrainCmd::Bdlstm(args) => bdlstm(args),
    }
}

fn latents(args: LatentsArgs) -> anyhow::Result<ExitCode> {
    let dir = &args.latents;
    encode_store_latents(
        &args.vae,
        &args.data,
        dir,
        args.shard,
        args.micro_batch as usize,
        args.backend,
        &mut |k, state| {
            let file = shard_file(dir, k);
            match state {
                FileState::Current => eprintln!("shard {k}: {} is current, kept", file.display()),
                FileState::Missing => eprintln!("shard {k}: encoded into {}", file.display()),
                FileState::Stale(why) => eprintln!("shard {k}: {} was stale ({why}), encoded again", file.display()),
            }
        },
    )?;
    Ok(ExitCode::SUCCESS)
}

fn rf(
    RfArgs {
        vae,
        init,
        latents,
        common: args,
    }: RfArgs,
) -> anyhow::Result<ExitCode> {
    let opts = RfRunOptions {
        run: args.options("rf")?,
        vae_run: vae,
        init,
        latents,
    };
    let outcome = match &args.resume {
        Some(run_dir) => resume_rf(run_dir, args.backend, &opts)?,
        None => {
            let mut cfg = RfRunConfig::load(args.config()?, &args.overrides.set)?;
            cfg.device.backend = args.backend.unwrap_or(cfg.device.backend);
            started(train_rf(&cfg, &opts)?)
        }
    };
    Ok(report(&outcome))
}

fn bdlstm(
    BdlstmArgs {
        vae,
        variant,
        common: args,
    }: BdlstmArgs,
) -> anyhow::Result<ExitCode> {
    let opts = BdlstmRunOptions {
        run: args.options("bdlstm")?,
        vae_run: vae,
    };
    let outcome = match &args.resume {
        Some(run_dir) => resume_bdlstm(run_dir, args.backend, &opts)?,
        None => {
            let mut cfg = BdlstmRunConfig::load(args.config()?, &args.overrides.set)?;
            cfg.device.backend = args.backend.unwrap_or(cfg.device.backend);
            match variant.as_deref() {
                Some("acap") => cfg.model.variant = BdlstmVariant::Acap,
                Some(_) => cfg.model.variant = BdlstmVariant::Latent,
                None => {}
            }
            started(train_bdlstm(&cfg, &opts)?)
        }
    };
    Ok(report(&outcome))
}

fn vae(VaeArgs { common: args }: VaeArgs) -> anyhow::Result<ExitCode> {
    let opts = args.options("vae")?;
    let outcome = match &args.resume {
        Some(run_dir) => resume_vae(run_dir, args.backend, &opts)?,
        None => {
            let mut cfg = VaeRunConfig::load(args.config()?, &args.overrides.set)?;
            cfg.device.backend = args.backend.unwrap_or(cfg.device.backend);
            started(train_vae(&cfg, &opts)?)
        }
    };
    Ok(report(&outcome))
}

/// Says where a new run went.
fn started((run, outcome): (RunFolder, Outcome)) -> Outcome {
    println!("run folder: {}", run.root().display());
    outcome
}

fn report(outcome: &Outcome) -> ExitCode {
    match outcome {
        Outcome::Finished { steps, checkpoint } => {
            println!("finished {steps} steps; checkpoint {}", checkpoint.display());
            ExitCode::SUCCESS
        }
        Outcome::Interrupted { step, checkpoint } => {
            println!(
                "interrupted after step {step}; checkpoint {} (resume with --resume)",
                checkpoint.display()
            );
            ExitCode::from(130)
        }
    }
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Run config to time: an RF preset (`configs/rf/*.toml`, random latents, no store), a VAE preset
    /// (`configs/vae/*.toml`, trains on `--data`) or a BD-LSTM preset (`configs/bdlstm/*.toml`, trains on `--data`,
    /// the latent variant with `--vae`); told apart by its `[rf]`, `[vae]` or `[bdlstm]` table.
    #[arg(long, default_value = "configs/vae/tiny.toml")]
    config: PathBuf,
    #[command(flatten)]
    overrides: ConfigArgs,
    /// Dataset store folder (VAE and BD-LSTM presets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// The frozen VAE run whose latents a latent BD-LSTM preset trains on.
    #[arg(long)]
    vae: Option<PathBuf>,
    /// Optimiser steps per backend; the first is a warm-up and the median is over the others.
    #[arg(long, default_value_t = 10)]
    steps: u64,
    /// Backends to compare.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), num_args = 1.., default_values = ["flex", "ndarray"])]
    backends: Vec<Backend>,
    /// Override `[device] precision` (bf16: GPU backends that compute in it; f16 is refused for training).
    #[arg(long, value_parser = enum_parser(&Precision::ALL))]
    precision: Option<Precision>,
    /// Clips per timed step (RF default: the preset's `train.micro_batch`; VAE default: the preset's global batch;
    /// given, one micro-batch of this size per step, no accumulation).
    #[arg(long)]
    micro_batch: Option<usize>,
    /// RF presets: FPS tokens P per clip (default: the stores' P, 512).
    #[arg(long)]
    tokens: Option<usize>,
    /// RF presets: the device's peak in TFLOP/s (e.g. 989 for an H100 SXM, bf16 dense); prints the achieved
    /// model FLOP/s as a fraction of it.
    #[arg(long)]
    peak_tflops: Option<f64>,
}

/// `any4d bench train`: times `--steps` steps of the preset on each backend.
pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if args.steps < 2 {
        bail!("--steps must be at least 2: the first step is a warm-up and is not timed");
    }
    if args.backends.is_empty() {
        bail!("--backends needs at least one backend");
    }
    match RunConfig::load(&args.config, &args.overrides.set)? {
        RunConfig::Rf(cfg) => bench_rf(&args, &cfg),
        RunConfig::Vae(cfg) => bench_vae(&args, &cfg),
        RunConfig::Bdlstm(cfg) => bench_bdlstm(&args, &cfg),
    }
}

fn bench_rf(args: &BenchArgs, cfg: &RfRunConfig) -> anyhow::Result<ExitCode> {
    if args.data.is_some() {
        println!("note: --data is not used with an RF preset (the benchmark draws random latents)");
    }
    if args.vae.is_some() {
        bail!("--vae applies to latent BD-LSTM presets only (an RF preset is timed on random latents)");
    }
    let shape = RfShape {
        batch: args.micro_batch.unwrap_or(cfg.train.micro_batch),
        tokens: args.tokens.unwrap_or(DEFAULT_P),
        text_len: cfg.text.max_len,
    };
    if shape.batch == 0 || shape.tokens == 0 {
        bail!("--micro-batch and --tokens must be positive");
    }
    if let Some(peak) = args.peak_tflops
        && !(peak.is_finite() && peak > 0.0)
    {
        bail!("--peak-tflops must be a positive number of TFLOP/s, got {peak}");
    }
    let precision = args.precision.unwrap_or(cfg.device.precision);
    let flops = rf_step_flops(cfg, shape);
    if cfg!(debug_assertions) {
        println!(
            "note: debug build of our crates (dependencies are optimised); a `--release` build gives representative \
             numbers"
        );
    }
    println!(
        "bench train: {} — RF step (text encoder + (R5) loss + backward + clip + AdamW) on random latents \
         [B {}, P {}, T {}, C {}], text L {}, conditioning {:?}, precision {precision:?}; {} steps per backend, median \
         of the last {}",
        args.config.display(),
        shape.batch,
        shape.tokens,
        cfg.model.frames,
        cfg.model.channels,
        shape.text_len,
        cfg.model.conditioning,
        args.steps,
        args.steps - 1
    );
    println!(
        "model FLOPs per step: {:.3} GFLOP = B {} × (MMDiT {:.3} + text encoder {:.3} GFLOP per clip; training = \
         3 × forward)",
        flops.step / 1e9,
        shape.batch,
        flops.mmdit_per_clip as f64 / 1e9,
        flops.text_per_clip as f64 / 1e9
    );
    println!(
        "{:<8} {:>11} {:>10} {:>9} {:>10} {:>11} {:>10} {:>8}",
        "backend", "micro_batch", "median_s", "steps/s", "samples/s", "GFLOP/step", "GFLOP/s", "of_peak"
    );
    for &b in &args.backends {
        backend::check_training(b, precision)?;
        let device = backend::device(b, precision)?;
        let secs = time_rf_steps(cfg, shape, args.steps, &device).with_context(|| format!("backend {b}"))?;
        let step_s = median(&secs[1..]);
        let achieved = flops.step / step_s;
        let of_peak = args
            .peak_tflops
            .map_or_else(|| "-".to_string(), |p| format!("{:.1}%", 100.0 * achieved / (p * 1e12)));
        println!(
            "{:<8} {:>11} {step_s:>10.4} {:>9.3} {:>10.2} {:>11.3} {:>10.2} {of_peak:>8}",
            b.to_string(),
            shape.batch,
            1.0 / step_s,
            shape.batch as f64 / step_s,
            flops.step / 1e9,
            achieved / 1e9
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// The same VAE preset for `--steps` steps on each backend; prints steps/s (median over the steps after the first,
/// which includes start-up).
fn bench_vae(args: &BenchArgs, base: &VaeRunConfig) -> anyhow::Result<ExitCode> {
    let data = store_for_trained_preset(args, "a VAE preset")?;
    if args.vae.is_some() {
        bail!("--vae applies to latent BD-LSTM presets only");
    }
    bench_runs(args, |backend, runs, name| {
        let mut cfg = base.clone();
        bench_settings(args, backend, &mut cfg.device, &mut cfg.train);
        Ok(time_vae_steps(cfg, data, args.steps, runs, name)?)
    })
}

/// A BD-LSTM preset for `--steps` steps on each backend: the latent variant on the VAE of `--vae`, the ACAP variant on
/// the store's vertices (docs/method.md §5.3).
fn bench_bdlstm(args: &BenchArgs, base: &BdlstmRunConfig) -> anyhow::Result<ExitCode> {
    let data = store_for_trained_preset(args, "a BD-LSTM preset")?;
    let vae = match (base.model.variant, &args.vae) {
        (BdlstmVariant::Latent, Some(vae)) => Some(vae.as_path()),
        (BdlstmVariant::Latent, None) => bail!(
            "config {}: a latent BD-LSTM preset trains on a VAE's latents: give --vae RUN",
            args.config.display()
        ),
        (BdlstmVariant::Acap, Some(_)) => bail!(
            "config {}: the ACAP variant trains on the store's vertices, not on VAE latents: drop --vae",
            args.config.display()
        ),
        (BdlstmVariant::Acap, None) => None,
    };
    bench_runs(args, |backend, runs, name| {
        let mut cfg = base.clone();
        bench_settings(args, backend, &mut cfg.device, &mut cfg.train);
        Ok(time_bdlstm_steps(cfg, data, vae, args.steps, runs, name)?)
    })
}

/// A timed run's backend, `--precision` and `--micro-batch` (one micro-batch per step: the step time of that many
/// clips, no accumulation).
fn bench_settings(args: &BenchArgs, backend: Backend, device: &mut DeviceConfig, train: &mut TrainConfig) {
    device.backend = backend;
    if let Some(p) = args.precision {
        device.precision = p;
    }
    if let Some(mb) = args.micro_batch {
        train.micro_batch = mb;
        train.batch_size = mb;
    }
}

/// The store a VAE or BD-LSTM preset trains on; the RF-only flags are refused.
fn store_for_trained_preset<'a>(args: &'a BenchArgs, what: &str) -> anyhow::Result<&'a Path> {
    let Some(data) = &args.data else {
        bail!(
            "config {}: {what} trains on a store: give --data STORE (`any4d data synth|import`)",
            args.config.display()
        );
    };
    if args.tokens.is_some() || args.peak_tflops.is_some() {
        bail!("--tokens and --peak-tflops apply to RF presets only");
    }
    Ok(data)
}

/// Runs `time(backend, runs folder, run name)` for every backend and prints one row each.
fn bench_runs(
    args: &BenchArgs,
    time: impl Fn(Backend, &Path, &str) -> anyhow::Result<TrainThroughput>,
) -> anyhow::Result<ExitCode> {
    let runs = tempfile::Builder::new()
        .prefix("any4d-bench-train-")
        .tempdir()
        .context("creating the folder of the benchmark runs")?
        .keep();
    println!(
        "backend  steps  median steps/s  median samples/s  wall s   ({})",
        args.config.display()
    );
    for &backend in &args.backends {
        let t = time(backend, &runs, &format!("bench-{backend}"))?;
        println!(
            "{:<8} {:>5}  {:>14.3}  {:>16.2}  {:>6.1}",
            backend.to_string(),
            args.steps,
            t.steps_per_s,
            t.samples_per_s,
            t.wall_s
        );
    }
    println!("(run folders under {})", runs.display());
    Ok(ExitCode::SUCCESS)
}
