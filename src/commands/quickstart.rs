//! `any4d quickstart`: the README's first command; parses its options and calls `any4d_train::quickstart`.

use std::process::ExitCode;

use clap::Args;

use any4d_train::progress::ProgressMode;
use any4d_train::quickstart::{QuickstartOptions, quickstart};

use super::stop_on_ctrl_c;

#[derive(Args, Debug)]
pub struct QuickstartArgs {
    /// Output folder for the dataset, runs, table and pictures (`<out>-2`, … when it exists).
    #[arg(long, default_value = "runs/quickstart")]
    pub out: std::path::PathBuf,
    /// Procedural clips to synthesise.
    #[arg(long, default_value_t = 96)]
    pub clips: usize,
    /// Seed of the procedural clips.
    #[arg(long, default_value_t = 666)]
    pub seed: u64,
    /// Largest vertex count of the clips (512..=4096; small is fast).
    #[arg(long, default_value_t = 768)]
    pub max_vertices: usize,
    /// VAE optimiser steps (the quickstart's time budget; the tiny preset itself says 60).
    #[arg(long, default_value_t = 280)]
    pub vae_steps: u64,
    /// Optimiser steps of each RF (the quickstart's time budget; the tiny preset itself says 60).
    #[arg(long, default_value_t = 300)]
    pub rf_steps: u64,
    /// Validation clips in the evaluation manifest.
    #[arg(long, default_value_t = 12)]
    pub eval_clips: usize,
    /// ODE grid points of the RF samplers (the paper uses 64).
    #[arg(long, default_value_t = 16)]
    pub n_grid: usize,
    /// Shipped models evaluated beside the ones trained now, on the same clips and keyframes (skipped when the
    /// folder has no `rf/`).
    #[arg(long, default_value = "weights/small")]
    pub shipped: std::path::PathBuf,
}

pub fn exec(args: QuickstartArgs) -> anyhow::Result<ExitCode> {
    let stop = stop_on_ctrl_c()?;
    let opts = QuickstartOptions {
        out: args.out,
        clips: args.clips,
        seed: args.seed,
        max_vertices: args.max_vertices,
        vae_steps: Some(args.vae_steps),
        rf_steps: Some(args.rf_steps),
        eval_clips: args.eval_clips,
        n_grid: args.n_grid,
        shipped: Some(args.shipped),
        progress: ProgressMode::Auto,
        stop,
    };
    let report = quickstart(&opts, &|line| println!("{line}"))?;
    println!();
    match &report.combined {
        Some(table) => println!("{table}"),
        None => println!("{}", report.table.markdown),
    }
    println!("Results are in {}:", report.out.display());
    println!("  data (procedural store)   {}", report.data.display());
    println!("  VAE run                   {}", report.vae_run.display());
    println!("  keyframe RF run (ours)    {}", report.rf_run.display());
    println!("  baseline RF run           {}", report.baseline_run.display());
    println!("  evaluation                {}", report.eval_dir.display());
    println!("    combined.md (this table, with the shipped models' rows; their own summary in shipped/),");
    println!("    summary.md / summary.csv (the quickstart's rows), clips.parquet (per clip), manifest.json,");
    println!("    rmse_vs_kx.png (plot), strips/*.png (ground truth above, prediction below), predictions/,");
    println!("    view/*.html (open in a browser: every method beside the ground truth, playing)");
    println!("  each run folder has config.toml, log.txt, metrics.csv, loss.png and checkpoints/");
    Ok(ExitCode::SUCCESS)
}
