//! `any4d quickstart`: the whole method on procedural clips in minutes on a CPU — synthesise a store, train a
//! tiny frame-wise VAE, a tiny keyframe-conditioned RF and a tiny non-keyframe RF (the paper's Baseline), then
//! score them beside linear interpolation and the static nearest keyframe on one protocol (P-Table 1 shape).
//! Sizes come from `configs/{vae,rf}/tiny.toml` (embedded at build time, so the binary runs anywhere).

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::prelude::Device;

use any4d_data::store::write_synth;
use any4d_data::synth::SynthConfig;
use any4d_eval::methods::MethodKind;
use any4d_eval::tables::short_horizon::{self, ShortHorizon};
use any4d_eval::tables::summary::{TableHeader, markdown};
use any4d_eval::tables::{Items, Protocol, TableOptions, TableReport, run_protocol};

use crate::backend;
use crate::config::{Duration, Embedded};
use crate::error::{Result, TrainError};
use crate::evaluate::{LearnedRuns, SamplingSetup, build_methods};
use crate::loop_common::{Outcome, RunOptions, StopFlag};
use crate::progress::ProgressMode;
use crate::rf_loop::{RfRunConfig, RfRunOptions, train_rf};
use crate::vae_loop::{VaeRunConfig, train_vae};

/// The presets the quickstart runs, embedded with the files their `extends` chains name.
const PRESETS: Embedded = Embedded(&[
    ("configs/vae/tiny.toml", include_str!("../../configs/vae/tiny.toml")),
    ("configs/rf/tiny.toml", include_str!("../../configs/rf/tiny.toml")),
    (
        "configs/rf/baseline_tiny.toml",
        include_str!("../../configs/rf/baseline_tiny.toml"),
    ),
]);

/// What the quickstart does; every default is chosen to finish in minutes on 2 cores.
#[derive(Debug, Clone)]
pub struct QuickstartOptions {
    /// Output folder (a fresh `<out>-<n>` is used when it exists: nothing is overwritten).
    pub out: PathBuf,
    /// Procedural clips to synthesise.
    pub clips: usize,
    /// Seed of the procedural clips.
    pub seed: u64,
    /// Largest vertex count of the procedural clips (the paper's filter 512..=4096; small is fast).
    pub max_vertices: usize,
    /// Optimiser steps of the VAE (the tiny preset's when `None`).
    pub vae_steps: Option<u64>,
    /// Optimiser steps of each RF (the tiny preset's when `None`).
    pub rf_steps: Option<u64>,
    /// Validation clips in the evaluation manifest.
    pub eval_clips: usize,
    /// ODE grid points of the samplers (the paper's 64 is slow on a CPU).
    pub n_grid: usize,
    /// Folder of shipped models (`weights/small`: `vae/`, `rf/`, `baseline-rf/`) evaluated on the same clips and
    /// keyframes as the quickstart's own; `None` or a folder without them skips that step.
    pub shipped: Option<PathBuf>,
    /// Progress display.
    pub progress: ProgressMode,
    /// Ctrl-C flag.
    pub stop: StopFlag,
}

/// Where the quickstart put things.
#[derive(Debug)]
pub struct QuickstartReport {
    pub out: PathBuf,
    pub data: PathBuf,
    pub vae_run: PathBuf,
    pub rf_run: PathBuf,
    pub baseline_run: PathBuf,
    pub eval_dir: PathBuf,
    pub table: TableReport,
    /// The quickstart's rows and the shipped models' rows in one table (when shipped models were found).
    pub combined: Option<String>,
}

/// A folder that does not exist yet: `out`, else `out-2`, `out-3`, …
fn fresh_folder(out: &Path) -> PathBuf {
    if !out.exists() {
        return out.to_path_buf();
    }
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "quickstart".into());
    (2..)
        .map(|n| out.with_file_name(format!("{name}-{n}")))
        .find(|p| !p.exists())
        .expect("an unbounded range always yields a free name")
}

fn finished(what: &str, outcome: Outcome) -> Result<()> {
    match outcome {
        Outcome::Finished { .. } => Ok(()),
        Outcome::Interrupted { step, checkpoint } => Err(TrainError::Loop(format!(
            "{what} interrupted at step {step}; checkpoint kept at {}",
            checkpoint.display()
        ))),
    }
}

/// Runs the whole quickstart; `say` receives one line per stage.
pub fn quickstart(opts: &QuickstartOptions, say: &dyn Fn(&str)) -> Result<QuickstartReport> {
    let out = fresh_folder(&opts.out);
    let data = out.join("data");
    let runs_dir = out.join("runs");
    let started = Instant::now();
    let stage = |msg: String| say(&format!("[{:>5.0} s] {msg}", started.elapsed().as_secs_f64()));

    // The presets are embedded; errors name the repository file they came from.
    let mut vae_cfg = VaeRunConfig::load_with(&PRESETS, Path::new("configs/vae/tiny.toml"), &[])?;
    let mut rf_cfg = RfRunConfig::load_with(&PRESETS, Path::new("configs/rf/tiny.toml"), &[])?;
    let mut base_cfg = RfRunConfig::load_with(&PRESETS, Path::new("configs/rf/baseline_tiny.toml"), &[])?;
    if let Some(n) = opts.vae_steps {
        vae_cfg.train.duration = Duration::Steps(n);
        // Four validations (each encodes every frame of the VAL clips, the slow part of a short run).
        vae_cfg.train.valid_every = (n / 4).max(1);
        vae_cfg.train.checkpoint_every = (n / 4).max(1);
    }
    if let Some(n) = opts.rf_steps {
        rf_cfg.train.duration = Duration::Steps(n);
        base_cfg.train.duration = Duration::Steps(n);
    }
    // Every stage runs on the CPU backend that `configs/*/tiny.toml` names; check it before creating anything.
    backend::check_training(vae_cfg.device.backend, vae_cfg.device.precision)?;

    stage(format!(
        "1/5 synthesising {} procedural clips into {}",
        opts.clips,
        data.display()
    ));
    let synth = SynthConfig {
        clips: opts.clips,
        seed: opts.seed,
        frames: 16,
        min_vertices: 512,
        max_vertices: opts.max_vertices,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    let report = write_synth(&synth, &data)?;
    stage(format!(
        "      {} clips: {} train, {} validation",
        report.total, report.train, report.val
    ));

    stage("2/5 training the tiny frame-wise VAE".into());
    let (vae_run, outcome) = train_vae(
        &vae_cfg,
        &RunOptions {
            data: data.clone(),
            runs_dir: runs_dir.clone(),
            name: "vae".into(),
            progress: opts.progress,
            stop: opts.stop.clone(),
            parallel: None,
        },
    )?;
    finished("VAE training", outcome)?;

    let rf_opts = |name: &str| RfRunOptions {
        run: RunOptions {
            data: data.clone(),
            runs_dir: runs_dir.clone(),
            name: name.into(),
            progress: opts.progress,
            stop: opts.stop.clone(),
            parallel: None,
        },
        vae_run: Some(vae_run.root().to_path_buf()),
        init: None,
        latents: None,
    };
    stage("3/5 training the tiny keyframe-conditioned RF (ours)".into());
    let (rf_run, outcome) = train_rf(&rf_cfg, &rf_opts("rf"))?;
    finished("RF training", outcome)?;
    stage("4/5 training the tiny non-keyframe RF (the paper's Baseline, sampled with replacement)".into());
    let (baseline_run, outcome) = train_rf(&base_cfg, &rf_opts("baseline-rf"))?;
    finished("baseline RF training", outcome)?;

    stage(format!(
        "5/5 evaluating on {} validation clips, K_x = 0..3",
        opts.eval_clips
    ));
    let device = backend::device(rf_cfg.device.backend, rf_cfg.device.precision)?;
    let runs = LearnedRuns {
        rf: Some(rf_run.root().to_path_buf()),
        baseline_rf: Some(baseline_run.root().to_path_buf()),
        vae: Some(vae_run.root().to_path_buf()),
        vae_b: None,
        bdlstm: None,
        bdlstm_acap: None,
        aam: None,
    };
    let kinds = [
        MethodKind::KeyframeRf,
        MethodKind::ReplacementRf,
        MethodKind::Lerp,
        MethodKind::StaticNearest,
    ];
    let sampling = SamplingSetup {
        n_grid: opts.n_grid,
        ..SamplingSetup::default()
    };
    let built = build_methods(&kinds, &runs, sampling, &device)?;
    let eval_dir = out.join("eval");
    let protocol = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            clips: opts.eval_clips,
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    let mut run_opts = TableOptions::new(data.clone(), eval_dir.clone());
    run_opts.methods = built.methods;
    run_opts.export_items = 3;
    run_opts.progress = !matches!(opts.progress, ProgressMode::Quiet);
    run_opts.header = TableHeader {
        text_encoder: "scratch".into(),
        checkpoints: built.checkpoints.into_iter().collect(),
        device: format!(
            "{:?} CPU; sampler midpoint on a {}-point grid, guidance 1.0 (paper: 64 points)",
            rf_cfg.device.backend, opts.n_grid
        ),
        ..TableHeader::default()
    };
    let table = run_protocol(&protocol, &run_opts)?;
    let combined = match opts.shipped.as_deref() {
        Some(dir) if dir.join("rf").is_dir() => {
            stage(format!(
                "6/6 evaluating the shipped models of {} on the same clips and keyframes",
                dir.display()
            ));
            Some(shipped_rows(dir, &table, &data, &eval_dir, sampling, &device, opts)?)
        }
        Some(dir) => {
            stage(format!("6/6 skipped: no shipped models in {}", dir.display()));
            None
        }
        None => None,
    };
    stage("done".into());
    Ok(QuickstartReport {
        out,
        data,
        vae_run: vae_run.root().to_path_buf(),
        rf_run: rf_run.root().to_path_buf(),
        baseline_run: baseline_run.root().to_path_buf(),
        eval_dir,
        table,
        combined,
    })
}

/// Evaluates the shipped RFs of `dir` on the manifest the quickstart table used and returns one Markdown table:
/// every row names where its weights came from.
fn shipped_rows(
    dir: &Path,
    table: &TableReport,
    data: &Path,
    eval_dir: &Path,
    sampling: SamplingSetup,
    device: &Device,
    opts: &QuickstartOptions,
) -> Result<String> {
    let runs = LearnedRuns {
        rf: Some(dir.join("rf")),
        baseline_rf: Some(dir.join("baseline-rf")),
        vae: Some(dir.join("vae")),
        vae_b: None,
        bdlstm: None,
        bdlstm_acap: None,
        aam: None,
    };
    let built = build_methods(
        &[MethodKind::KeyframeRf, MethodKind::ReplacementRf],
        &runs,
        sampling,
        device,
    )?;
    let protocol = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            clips: opts.eval_clips,
            manifest: Some(eval_dir.join("manifest.json")),
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    let mut run_opts = TableOptions::new(data.to_path_buf(), eval_dir.join("shipped"));
    run_opts.methods = built.methods;
    run_opts.export_items = 0;
    run_opts.progress = !matches!(opts.progress, ProgressMode::Quiet);
    let shipped = run_protocol(&protocol, &run_opts)?;
    let learned = |m: &str| matches!(m, "keyframe_rf" | "replacement_rf");
    let mut rows = Vec::new();
    for r in &table.rows {
        let mut r = r.clone();
        if learned(&r.method) {
            r.method = format!("{} (trained now)", r.method);
        }
        rows.push(r);
    }
    for r in &shipped.rows {
        let mut r = r.clone();
        r.method = format!("{} ({})", r.method, dir.display());
        rows.push(r);
    }
    let mut header = TableHeader {
        text_encoder: "scratch".into(),
        checkpoints: built
            .checkpoints
            .into_iter()
            .map(|(label, ckpt)| (format!("{label} ({})", dir.display()), ckpt))
            .collect(),
        device: format!(
            "CPU; sampler midpoint on a {}-point grid, guidance 1.0 (paper: 64 points)",
            sampling.n_grid
        ),
        ..TableHeader::default()
    };
    header.data = format!("{} (validation split)", data.display());
    header.manifest = eval_dir.join("manifest.json").display().to_string();
    let text = markdown(&short_horizon::LAYOUT, &rows, &header);
    let path = eval_dir.join("combined.md");
    std::fs::write(&path, &text).map_err(|e| TrainError::Setup(format!("{}: {e}", path.display())))?;
    Ok(text)
}

#[cfg(test)]
mod tests {
    use any4d_model::mmdit::KeyframeConditioning;

    use super::*;

    #[test]
    fn the_embedded_presets_resolve_as_the_repository_files_do() {
        let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
        for name in ["configs/rf/tiny.toml", "configs/rf/baseline_tiny.toml"] {
            let embedded = RfRunConfig::load_with(&PRESETS, Path::new(name), &[]).expect(name);
            assert_eq!(
                embedded,
                RfRunConfig::load(&root.join(name), &[]).expect(name),
                "{name}"
            );
        }
        let baseline = RfRunConfig::load_with(&PRESETS, Path::new("configs/rf/baseline_tiny.toml"), &[]).unwrap();
        assert_eq!(baseline.model.conditioning, KeyframeConditioning::ReplaceNoised);
        let vae = VaeRunConfig::load_with(&PRESETS, Path::new("configs/vae/tiny.toml"), &[]).unwrap();
        assert_eq!(
            vae,
            VaeRunConfig::load(&root.join("configs/vae/tiny.toml"), &[]).unwrap()
        );
    }
}
