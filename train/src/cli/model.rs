//! `any4d model …` and `any4d bench model`: parameter counts of the network a config describes, and RF
//! forward+backward time per clip. Parses arguments and the `[model]` table, calls `any4d_model::summary`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use any4d_model::dymesh_vae::DyMeshVaeConfig;
use any4d_model::frame_vae::FrameVaeConfig;
use any4d_model::mmdit::{KfMode, MmditConfig};
use any4d_model::summary::{format_report, param_report, time_rf_step, time_vae_reconstruct};
use anyhow::{Context, bail};
use burn::prelude::Device;
use clap::{Args, Subcommand, ValueEnum};

#[derive(Subcommand, Debug)]
pub enum ModelCmd {
    /// Parameter counts per submodule of the network in a config's `[model]` table.
    Summary(SummaryArgs),
}

#[derive(Args, Debug)]
pub struct SummaryArgs {
    /// A run config (e.g. configs/rf/paper.toml).
    #[arg(long)]
    pub config: PathBuf,
}

/// Network size benchmarked by `any4d bench model`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum BenchSize {
    /// configs/rf/paper.toml sizes (W 512, 12 blocks, P 512, L 77); VAE d 128 on N 2048 vertices.
    Paper,
    /// MmditConfig::tiny() with P 64, L 8; FrameVaeConfig::tiny() on N 256.
    Tiny,
}

/// CPU backend of the benchmark.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum CpuBackend {
    Flex,
    Ndarray,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Network size.
    #[arg(long, value_enum, default_value = "paper")]
    pub size: BenchSize,
    /// Clips per step.
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Timed steps (after one warm-up step).
    #[arg(long, default_value_t = 3)]
    pub iters: usize,
    /// CPU backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub backend: CpuBackend,
}

pub fn run(cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        ModelCmd::Summary(args) => summary(&args.config),
    }
}

/// The network a config's `[model]` table describes, told apart by its keys: `kf_mode` → rectified-flow MMDiT,
/// `frames` → sequence-wise DyMeshVAE, otherwise the frame-wise VAE.
pub enum ModelConfig {
    Rf(MmditConfig),
    FrameVae(FrameVaeConfig),
    DyMeshVae(DyMeshVaeConfig),
}

/// Reads the `[model]` table of a config file; errors name the file and field.
pub fn load_model_config(path: &Path) -> anyhow::Result<ModelConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let table: toml::Table =
        toml::from_str(&text).with_context(|| format!("{}: invalid TOML", path.display()))?;
    let Some(model) = table.get("model") else {
        bail!("{}: no [model] table", path.display());
    };
    let Some(model_table) = model.as_table() else {
        bail!("{}: `model` must be a table", path.display());
    };
    let ctx = || format!("{}: [model]", path.display());
    if model_table.contains_key("kf_mode") {
        let cfg: MmditConfig = model.clone().try_into().with_context(ctx)?;
        cfg.validate()
            .map_err(|msg| anyhow::anyhow!("{}: {msg}", path.display()))?;
        Ok(ModelConfig::Rf(cfg))
    } else if model_table.contains_key("frames") {
        Ok(ModelConfig::DyMeshVae(
            model.clone().try_into().with_context(ctx)?,
        ))
    } else {
        Ok(ModelConfig::FrameVae(
            model.clone().try_into().with_context(ctx)?,
        ))
    }
}

fn summary(path: &Path) -> anyhow::Result<ExitCode> {
    let device = Device::flex();
    let (title, rows) = match load_model_config(path)? {
        ModelConfig::Rf(cfg) => (
            format!(
                "{}: rectified-flow MMDiT, kf_mode {:?}, {} input / {} output channels per token",
                path.display(),
                cfg.kf_mode,
                cfg.in_channels(),
                cfg.out_channels()
            ),
            param_report(&cfg.init(&device)),
        ),
        ModelConfig::FrameVae(cfg) => (
            format!("{}: frame-wise mesh VAE", path.display()),
            param_report(&cfg.init(&device)),
        ),
        ModelConfig::DyMeshVae(cfg) => (
            format!("{}: sequence-wise DyMeshVAE", path.display()),
            param_report(&cfg.init(&device)),
        ),
    };
    print!("{}", format_report(&title, &rows));
    Ok(ExitCode::SUCCESS)
}

pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if args.batch == 0 || args.iters == 0 {
        bail!("--batch and --iters must be positive");
    }
    let (cfg, tokens, text_len) = match args.size {
        BenchSize::Paper => (MmditConfig::paper(KfMode::InputMask, 768), 512, 77),
        BenchSize::Tiny => (MmditConfig::tiny(), 64, 8),
    };
    let device = match args.backend {
        CpuBackend::Flex => Device::flex(),
        CpuBackend::Ndarray => Device::ndarray(),
    };
    let timing = time_rf_step(&cfg, args.batch, tokens, text_len, args.iters, &device);
    let vae_cfg = match args.size {
        BenchSize::Paper => FrameVaeConfig::new(),
        BenchSize::Tiny => FrameVaeConfig::tiny(),
    };
    let vertices = match args.size {
        BenchSize::Paper => 2048,
        BenchSize::Tiny => 256,
    };
    let vae = time_vae_reconstruct(
        &vae_cfg, args.batch, vertices, tokens, cfg.frames, args.iters, &device,
    )
    .map_err(|msg| anyhow::anyhow!("bench model: {msg}"))?;
    println!(
        "bench model: RF forward+backward, {:?} size (W {}, {} blocks, P {tokens}, L {text_len}), {:?}, batch {}, {} iters: \
         median {:.1} ms/step, {:.1} ms/clip",
        args.size,
        cfg.width,
        cfg.blocks,
        args.backend,
        args.batch,
        args.iters,
        timing.median_ms,
        timing.median_ms / args.batch as f64
    );
    println!(
        "bench model: frame-wise VAE encode+decode (posterior mean, no gradients), d {}, N {vertices}, P {tokens}, \
         T {}, {:?}, batch {}, {} iters: median {:.1} ms/step, {:.1} ms/clip",
        vae_cfg.width,
        cfg.frames,
        args.backend,
        args.batch,
        args.iters,
        vae.median_ms,
        vae.median_ms / args.batch as f64
    );
    Ok(ExitCode::SUCCESS)
}
