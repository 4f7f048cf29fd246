//! `any4d bench sample`: P-Table 4 (docs/method.md §6.4) on freshly initialised networks at a config's size, on any
//! backend — the timing part of the GPU check (`scripts/gpu_check.sh`), which needs no trained run.

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_eval::rollout::OverlapSource;
use any4d_eval::tables::summary::TableHeader;
use any4d_eval::tables::timing::Timing;
use any4d_eval::tables::{Protocol, TableOptions, run_protocol};
use any4d_train::backend::{self, Backend, Precision};
use clap::Args;

use super::enum_parser;

/// `any4d bench sample`: P-Table 4 on freshly initialised networks.
#[derive(Args, Debug)]
pub struct SampleBenchArgs {
    /// RF run config whose keyframe network is timed (weights freshly initialised, seeded).
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/rf/paper.toml"))]
    pub rf_config: PathBuf,
    /// Frame-wise VAE run config that encodes and decodes (weights freshly initialised).
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/vae/paper.toml"))]
    pub vae_config: PathBuf,
    /// Compute backend.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), default_value = "flex")]
    pub backend: Backend,
    /// Vertex counts (P-Table 4: 512,1024,2048,4096).
    #[arg(long, value_delimiter = ',', default_value = "512,1024,2048,4096")]
    pub vertices: Vec<usize>,
    /// Frame counts: 16 = one window, 31 = the two-stage rollout.
    #[arg(long, value_delimiter = ',', default_value = "16,31")]
    pub frames: Vec<usize>,
    /// Float precision of the networks (f16, bf16: GPU backends only; the paper times f32).
    #[arg(long, value_parser = enum_parser(&Precision::ALL), default_value = "f32")]
    pub precision: Precision,
    /// Timed repetitions after one warm-up (median reported).
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
    /// Grid points of the midpoint solver (the paper: 64, i.e. 63 steps).
    #[arg(long, default_value_t = 64)]
    pub n_grid: usize,
    /// Output folder for summary.md / summary.csv.
    #[arg(long)]
    pub out: PathBuf,
}

/// `any4d bench sample`: encode → sample → decode seconds per clip of ours at the configs' sizes on `--backend`,
/// with freshly initialised weights (no trained run needed), through the P-Table 4 protocol.
pub fn bench_sample(args: SampleBenchArgs) -> anyhow::Result<ExitCode> {
    use any4d_train::bench::untrained_keyframe_method;
    use any4d_train::rf_loop::RfRunConfig;
    use any4d_train::vae_loop::VaeRunConfig;

    let rf = RfRunConfig::load(&args.rf_config, &[])?;
    let vae = VaeRunConfig::load(&args.vae_config, &[])?;
    let device = backend::device(args.backend, args.precision)?;
    let method = untrained_keyframe_method(&rf, &vae, args.n_grid, &device)?;
    let mut opts = TableOptions::new(PathBuf::from("none"), args.out.clone());
    opts.methods = vec![method];
    opts.header = TableHeader {
        text_encoder: "scratch (untrained)".into(),
        checkpoints: [(
            "keyframe_rf".to_string(),
            format!(
                "untrained: {} + {}",
                args.rf_config.display(),
                args.vae_config.display()
            ),
        )]
        .into_iter()
        .collect(),
        device: format!(
            "{:?} ({}); midpoint sampler on a {}-point grid",
            args.backend, args.precision, args.n_grid
        ),
        ..TableHeader::default()
    };
    let protocol = Protocol::Timing(Timing {
        vertices: args.vertices.clone(),
        frames: args.frames.clone(),
        reps: args.reps,
        overlap_source: OverlapSource::GroundTruth,
    });
    let report = run_protocol(&protocol, &opts)?;
    println!("{}", report.markdown);
    println!("written to {}", args.out.display());
    Ok(ExitCode::SUCCESS)
}
