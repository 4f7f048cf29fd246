//! `any4d train vae|rf`: parse arguments, load the TOML, call the library
//! (`vae_loop`, `rf_loop`). Ctrl-C saves a checkpoint and exits.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};

use crate::backend::Backend;
use crate::loop_common::{Outcome, StopFlag};
use crate::multi_device::{Parallel, Strategy, resume_vae_data_parallel, train_vae_data_parallel};
use crate::progress::ProgressMode;
use crate::rf_loop::{RfRunConfig, RfRunOptions, resume_rf, train_rf};
use crate::vae_loop::{VaeRunConfig, VaeRunOptions, resume_vae, train_vae};

#[derive(Subcommand, Debug)]
pub enum TrainCmd {
    /// Train the mesh VAE (docs/method.md §3): `--config configs/vae/<preset>.toml --data STORE`.
    Vae(VaeArgs),
    /// Train the keyframe rectified flow on a frozen VAE (docs/method.md §4).
    Rf(RfArgs),
}

#[derive(Args, Debug)]
pub struct VaeArgs {
    #[command(flatten)]
    common: RunArgs,
}

#[derive(Args, Debug)]
pub struct RfArgs {
    /// The VAE run folder whose newest checkpoint encodes the clips (with `--resume`: optional, must be the
    /// run's own).
    #[arg(long, required_unless_present = "resume")]
    vae: Option<PathBuf>,
    #[command(flatten)]
    common: RunArgs,
}

/// The options `train vae` and `train rf` share.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Run config (`configs/vae/*.toml` or `configs/rf/*.toml`); not with `--resume`, which reads the run's own
    /// config.
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    config: Option<PathBuf>,
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
    #[arg(long, value_enum)]
    backend: Option<Backend>,
    /// Train data-parallel over these devices, comma-separated `BACKEND[:INDEX]` (`cuda:0,cuda:1`,
    /// `flex,flex`); the first holds the model and the optimiser. Replaces `[device] backend`.
    #[arg(long, conflicts_with = "backend")]
    devices: Option<String>,
    /// How the devices combine gradients: `ddp` (burn's all-reduce, NCCL; cuda only), `main-device` (gradients
    /// copied to the first device), `auto` (ddp on distinct cuda devices, main-device otherwise).
    #[arg(long, value_enum, default_value = "auto", requires = "devices")]
    strategy: Strategy,
    /// Folder of run folders.
    #[arg(long, default_value = "runs")]
    runs_dir: PathBuf,
}

impl RunArgs {
    /// `--devices` with `--strategy`, checked.
    fn parallel(&self) -> anyhow::Result<Option<Parallel>> {
        Ok(self
            .devices
            .as_deref()
            .map(|d| Parallel::parse(d, self.strategy))
            .transpose()?)
    }
}

pub fn run(cmd: TrainCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        TrainCmd::Vae(args) => vae(args),
        TrainCmd::Rf(args) => rf(args),
    }
}

fn rf(RfArgs { vae, common: args }: RfArgs) -> anyhow::Result<ExitCode> {
    let parallel = args.parallel()?;
    let stop = StopFlag::new();
    stop.install_ctrlc()?;
    let opts = RfRunOptions {
        data: args.data,
        vae_run: vae,
        runs_dir: args.runs_dir,
        name: args.run.unwrap_or_else(|| "rf".into()),
        progress: ProgressMode::Auto,
        stop,
        parallel,
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

fn vae(VaeArgs { common: args }: VaeArgs) -> anyhow::Result<ExitCode> {
    let devices = args.parallel()?;
    let stop = StopFlag::new();
    stop.install_ctrlc()?;
    let opts = VaeRunOptions {
        data: args.data,
        runs_dir: args.runs_dir,
        name: args.run.unwrap_or_else(|| "vae".into()),
        progress: ProgressMode::Auto,
        stop,
    };
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
