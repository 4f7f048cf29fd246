//! `any4d train vae|rf` and `any4d bench train`: parse arguments, load the TOML, call the library
//! (`vae_loop`, `rf_loop`). Ctrl-C saves a checkpoint and exits.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Subcommand};

use crate::backend::Backend;
use crate::config::Duration;
use crate::loop_common::{Outcome, StopFlag};
use crate::multi_device::{Parallel, Strategy, resume_vae_data_parallel, train_vae_data_parallel};
use crate::progress::ProgressMode;
use crate::rf_loop::{RfRunConfig, RfRunOptions, resume_rf, train_rf};
use crate::run_folder::{METRICS_FILE, read_table};
use crate::vae_loop::{VaeRunConfig, VaeRunOptions, resume_vae, train_vae};

#[derive(Subcommand, Debug)]
pub enum TrainCmd {
    /// Train the mesh VAE (SPEC §3): `--config configs/vae/<preset>.toml --data STORE`.
    Vae(VaeArgs),
    /// Train the keyframe rectified flow on a frozen VAE (SPEC §4).
    Rf(RfArgs),
}

#[derive(Args, Debug)]
pub struct VaeArgs {
    /// Run config (`configs/vae/*.toml`); not with `--resume`, which reads the run's own config.
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    config: Option<PathBuf>,
    /// Dataset store folder (`any4d data import|synth`).
    #[arg(long)]
    data: PathBuf,
    /// Run name: the run goes to `<runs>/<NAME>-<n>/` with the next free n.
    #[arg(long, default_value = "vae")]
    run: String,
    /// Continue this run folder from its newest checkpoint.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Override `[device] backend`.
    #[arg(long, value_enum)]
    backend: Option<Backend>,
    #[command(flatten)]
    parallel: ParallelArgs,
    /// Folder of run folders.
    #[arg(long, default_value = "runs")]
    runs_dir: PathBuf,
}

/// `--devices` and `--strategy`, shared by `train vae` and `train rf`.
#[derive(Args, Debug)]
pub struct ParallelArgs {
    /// Train data-parallel over these devices, comma-separated `BACKEND[:INDEX]` (`cuda:0,cuda:1`,
    /// `flex,flex`); the first holds the model and the optimiser. Replaces `[device] backend`.
    #[arg(long, conflicts_with = "backend")]
    devices: Option<String>,
    /// How the devices combine gradients: `ddp` (burn's all-reduce, NCCL; cuda only), `main-device` (gradients
    /// copied to the first device), `auto` (ddp on distinct cuda devices, main-device otherwise).
    #[arg(long, value_enum, default_value = "auto", requires = "devices")]
    strategy: Strategy,
}

impl ParallelArgs {
    fn parse(&self) -> anyhow::Result<Option<Parallel>> {
        Ok(self
            .devices
            .as_deref()
            .map(|d| Parallel::parse(d, self.strategy))
            .transpose()?)
    }
}

#[derive(Args, Debug)]
pub struct RfArgs {
    /// Run config (`configs/rf/*.toml`); not with `--resume`, which reads the run's own config.
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    config: Option<PathBuf>,
    /// The VAE run folder whose newest checkpoint encodes the clips (with `--resume`: optional, must be the
    /// run's own).
    #[arg(long, required_unless_present = "resume")]
    vae: Option<PathBuf>,
    /// Dataset store folder.
    #[arg(long)]
    data: PathBuf,
    /// Run name: the run goes to `<runs>/<NAME>-<n>/` with the next free n.
    #[arg(long, default_value = "rf")]
    run: String,
    /// Continue this run folder from its newest checkpoint.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Override `[device] backend`.
    #[arg(long, value_enum)]
    backend: Option<Backend>,
    #[command(flatten)]
    parallel: ParallelArgs,
    /// Folder of run folders.
    #[arg(long, default_value = "runs")]
    runs_dir: PathBuf,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// VAE run config to time (e.g. `configs/vae/tiny.toml`).
    #[arg(long, default_value = "configs/vae/tiny.toml")]
    config: PathBuf,
    /// Dataset store folder.
    #[arg(long)]
    data: PathBuf,
    /// Optimiser steps per backend.
    #[arg(long, default_value_t = 10)]
    steps: u64,
    /// Backends to compare.
    #[arg(long, value_enum, num_args = 1.., default_values = ["flex", "ndarray"])]
    backends: Vec<Backend>,
}

pub fn run(cmd: TrainCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        TrainCmd::Vae(args) => vae(args),
        TrainCmd::Rf(args) => rf(args),
    }
}

fn rf(args: RfArgs) -> anyhow::Result<ExitCode> {
    let stop = StopFlag::new();
    stop.install_ctrlc()?;
    let opts = RfRunOptions {
        data: args.data,
        vae_run: args.vae,
        runs_dir: args.runs_dir,
        name: args.run,
        progress: ProgressMode::Auto,
        stop,
        parallel: args.parallel.parse()?,
    };
    let outcome = match (args.resume, args.config) {
        (Some(run_dir), _) => resume_rf(&run_dir, args.backend, &opts)?,
        (None, Some(config)) => {
            let mut cfg = RfRunConfig::load(&config)?;
            if let Some(b) = args.backend {
                cfg.device.backend = b;
            }
            let (run, outcome) = train_rf(&cfg, &opts)?;
            println!("run folder: {}", run.root().display());
            outcome
        }
        (None, None) => anyhow::bail!("give --config or --resume"),
    };
    Ok(report(&outcome))
}

fn vae(args: VaeArgs) -> anyhow::Result<ExitCode> {
    let stop = StopFlag::new();
    stop.install_ctrlc()?;
    let opts = VaeRunOptions {
        data: args.data,
        runs_dir: args.runs_dir,
        name: args.run,
        progress: ProgressMode::Auto,
        stop,
    };
    let devices = args.parallel.parse()?;
    let outcome = match (args.resume, args.config) {
        (Some(run_dir), _) => match &devices {
            Some(d) => resume_vae_data_parallel(&run_dir, &opts, d)?,
            None => resume_vae(&run_dir, args.backend, &opts)?,
        },
        (None, Some(config)) => {
            let mut cfg = VaeRunConfig::load(&config)?;
            if let Some(b) = args.backend {
                cfg.device.backend = b;
            }
            let (run, outcome) = match &devices {
                Some(d) => train_vae_data_parallel(&cfg, &opts, d)?,
                None => train_vae(&cfg, &opts)?,
            };
            println!("run folder: {}", run.root().display());
            outcome
        }
        (None, None) => anyhow::bail!("give --config or --resume"),
    };
    Ok(report(&outcome))
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

/// `any4d bench train`: the same VAE preset for `--steps` steps on each backend; prints steps/s (median over
/// the steps after the first, which includes start-up).
pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    let base = VaeRunConfig::load(&args.config)?;
    let runs = tempfile_dir()?;
    println!(
        "backend  steps  median steps/s  median samples/s  wall s   ({})",
        args.config.display()
    );
    for backend in &args.backends {
        let mut cfg = base.clone();
        cfg.device.backend = *backend;
        cfg.train.duration = Duration::Steps(args.steps);
        cfg.train.checkpoint_every = args.steps;
        cfg.train.valid_every = args.steps;
        let opts = VaeRunOptions {
            data: args.data.clone(),
            runs_dir: runs.clone(),
            name: format!("bench-{backend}"),
            progress: ProgressMode::Quiet,
            stop: StopFlag::new(),
        };
        let t0 = Instant::now();
        let (run, _) = train_vae(&cfg, &opts)?;
        let wall = t0.elapsed().as_secs_f64();
        let table = read_table(&run.path(METRICS_FILE))?;
        let col = |name: &str| table.header.iter().position(|h| h == name).map(|i| i - 1);
        let (Some(sps), Some(xps)) = (col("steps_per_s"), col("samples_per_s")) else {
            anyhow::bail!("metrics.csv lacks the throughput columns");
        };
        let median = |c: usize| {
            let mut v: Vec<f64> = table.rows.iter().skip(1).map(|r| r.1[c]).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        };
        println!(
            "{backend:<8} {:>5}  {:>14.3}  {:>16.2}  {wall:>6.1}",
            args.steps,
            median(sps),
            median(xps)
        );
    }
    println!("(run folders under {})", runs.display());
    Ok(ExitCode::SUCCESS)
}

fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)?
        .as_secs();
    let dir = std::env::temp_dir().join(format!("any4d-bench-train-{secs}-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}
