//! `any4d bench train`: training throughput of a run preset on each backend. An RF preset
//! (`configs/rf/*.toml`) times the RF training step at the preset's size on random standardised latents — no VAE
//! run and no store needed — and reports model FLOP/s (optionally as a fraction of a given peak); a VAE preset
//! (`configs/vae/*.toml`) trains on a store through `train_vae` and reads the throughput from `metrics.csv`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use any4d_data::store::DEFAULT_P;
use any4d_model::rectified_flow::{RfBatch, rf_training_loss};
use any4d_model::summary::median;
use anyhow::{Context, bail};
use burn::optim::GradientsParams;
use burn::prelude::{Bool, Device, Int, Tensor, TensorData};
use burn::tensor::Distribution;
use clap::Args;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::{self, Backend, Precision};
use crate::config::Duration;
use crate::loop_common::{StopFlag, clip_global_norm, scalar, step_seed};
use crate::progress::ProgressMode;
use crate::rf_loop::{RfRunConfig, draw_keyframe_mask};
use crate::run_folder::{METRICS_FILE, read_table};
use crate::vae_loop::{VaeRunConfig, VaeRunOptions, train_vae};

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Run config to time: an RF preset (`configs/rf/*.toml`, random latents, no store) or a VAE preset
    /// (`configs/vae/*.toml`, trains on `--data`); told apart by its `[rf]` or `[vae]` table.
    #[arg(long, default_value = "configs/vae/tiny.toml")]
    config: PathBuf,
    /// Dataset store folder (VAE presets only).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Optimiser steps per backend; the first is a warm-up and the median is over the others.
    #[arg(long, default_value_t = 10)]
    steps: u64,
    /// Backends to compare.
    #[arg(long, value_enum, num_args = 1.., default_values = ["flex", "ndarray"])]
    backends: Vec<Backend>,
    /// Override `[device] precision` (bf16: cuda only).
    #[arg(long, value_enum)]
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
    match Preset::load(&args.config)? {
        Preset::Rf(cfg) => bench_rf(&args, &cfg),
        Preset::Vae(cfg) => bench_vae(&args, &cfg),
    }
}

/// A run preset, told apart by its sections.
enum Preset {
    /// Has `[rf]`: parsed by [`RfRunConfig::parse`].
    Rf(Box<RfRunConfig>),
    /// Has `[vae]`: parsed by [`VaeRunConfig::parse`].
    Vae(Box<VaeRunConfig>),
}

impl Preset {
    /// Reads `path`; errors name the file and say what is wrong.
    fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("config {}: cannot read", path.display()))?;
        let table: toml::Table =
            toml::from_str(&text).with_context(|| format!("config {}: invalid TOML", path.display()))?;
        if table.contains_key("rf") {
            Ok(Preset::Rf(Box::new(RfRunConfig::parse(&text, path)?)))
        } else if table.contains_key("vae") {
            Ok(Preset::Vae(Box::new(VaeRunConfig::parse(&text, path)?)))
        } else {
            bail!(
                "config {}: neither an RF run config (no [rf] table, see configs/rf/) nor a VAE run config (no [vae] \
                 table, see configs/vae/)",
                path.display()
            )
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// RF presets

/// Sizes of the timed RF batch.
#[derive(Clone, Copy, Debug)]
struct RfShape {
    /// Clips per step B.
    batch: usize,
    /// FPS tokens P.
    tokens: usize,
    /// Caption tokens L (`text.max_len`).
    text_len: usize,
}

/// The inputs of one RF step, drawn before the clock starts.
struct RfInputs {
    z0: Tensor<3>,
    z: Tensor<4>,
    mask: Tensor<2>,
    ids: Tensor<2, Int>,
    pad: Tensor<2, Bool>,
    keep_txt: Tensor<1>,
    eps: Tensor<4>,
    tau: Tensor<1>,
}

/// Random standardised latents z₀ `[B, P, C]` and Z `[B, P, T, C]` ~ N(0, I) (what §3.4's standardisation
/// aims at), keyframe masks from [`draw_keyframe_mask`], uniform token ids without padding, keep_txt with the
/// preset's CFG dropout, ε and τ as in training. Host draws from `rng`, the rest from the device stream.
fn rf_inputs(cfg: &RfRunConfig, shape: RfShape, rng: &mut ChaCha8Rng, device: &Device) -> RfInputs {
    let RfShape {
        batch: b,
        tokens: p,
        text_len: l,
    } = shape;
    let (t, c) = (cfg.model.frames, cfg.model.channels);
    let normal = Distribution::Normal(0.0, 1.0);
    let mask: Vec<f32> = (0..b)
        .flat_map(|_| draw_keyframe_mask(&cfg.rf, cfg.model.kf_mode, t, rng))
        .map(|m| f32::from(u8::from(m)))
        .collect();
    let ids: Vec<i64> = (0..b * l)
        .map(|_| rng.random_range(0..cfg.text.vocab_size as i64))
        .collect();
    let keep: Vec<f32> = (0..b)
        .map(|_| f32::from(u8::from(!rng.random_bool(cfg.rf.text_dropout))))
        .collect();
    RfInputs {
        z0: Tensor::random([b, p, c], normal, device),
        z: Tensor::random([b, p, t, c], normal, device),
        mask: Tensor::from_data(TensorData::new(mask, [b, t]), device),
        ids: Tensor::from_data(TensorData::new(ids, [b, l]), device),
        pad: Tensor::from_data(TensorData::new(vec![false; b * l], [b, l]), device),
        keep_txt: Tensor::from_data(TensorData::new(keep, [b]), device),
        eps: Tensor::random([b, p, t, c], normal, device),
        tau: cfg.rf.tau_sampler.sample(b, device),
    }
}

/// Seconds of each of `steps` RF training steps on `device` (the first is the warm-up): caption encoder
/// forward, (R5) through [`rf_training_loss`] as `RfObjective::loss` computes it, backward, global-norm clipping
/// and the AdamW step of the training loop, then a device sync. The model is built at the preset's size with
/// the preset's largest vocabulary; `impute_until` uses Z as its keyframe latents (the VAE encoding of noisy
/// keyframes is not timed).
fn time_rf_steps(cfg: &RfRunConfig, shape: RfShape, steps: u64, device: &Device) -> anyhow::Result<Vec<f64>> {
    let ad = device.clone().autodiff();
    ad.seed(cfg.train.seed);
    let mut model = cfg.model_config(cfg.text.vocab_size).init(&ad);
    let mut optim = cfg.optim.init();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.train.seed);
    let loss_options = cfg.loss_options();
    let sync = |what: &str| ad.sync().map_err(|e| anyhow::anyhow!("device sync {what}: {e:?}"));
    let mut secs = Vec::new();
    for step in 1..=steps {
        ad.seed(step_seed(cfg.train.seed, step));
        let x = rf_inputs(cfg, shape, &mut rng, &ad);
        sync("before the step")?;
        let start = Instant::now();
        let text = model.text.forward(x.ids, x.pad);
        let batch = RfBatch {
            z0: x.z0,
            z: x.z.clone(),
            z_key: x.z,
            mask: x.mask,
            text,
            keep_txt: x.keep_txt,
        };
        let loss = rf_training_loss(&model.mmdit, &batch, x.eps, x.tau, &loss_options); // (R5)
        let value = scalar(loss.clone());
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let (grads, norm) = clip_global_norm(&model, grads, cfg.optim.grad_clip);
        model = optim.step(cfg.optim.lr, model, grads);
        sync("after the step")?;
        secs.push(start.elapsed().as_secs_f64());
        if !(value.is_finite() && norm.is_finite()) {
            bail!("step {step}: non-finite loss {value} or gradient norm {norm}");
        }
    }
    Ok(secs)
}

fn bench_rf(args: &BenchArgs, cfg: &RfRunConfig) -> anyhow::Result<ExitCode> {
    if args.data.is_some() {
        println!("note: --data is not used with an RF preset (the benchmark draws random latents)");
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
    let mmdit = cfg.model.forward_flops(shape.tokens, shape.text_len).training_step();
    let text = cfg
        .model_config(cfg.text.vocab_size)
        .text
        .forward_flops()
        .training_step();
    let step_flops = (mmdit + text) as f64 * shape.batch as f64;
    if cfg!(debug_assertions) {
        println!(
            "note: debug build of our crates (dependencies are optimised); a `--release` build gives representative \
             numbers"
        );
    }
    println!(
        "bench train: {} — RF step (text encoder + (R5) loss + backward + clip + AdamW) on random latents \
         [B {}, P {}, T {}, C {}], text L {}, kf_mode {:?}, precision {precision:?}; {} steps per backend, median of the \
         last {}",
        args.config.display(),
        shape.batch,
        shape.tokens,
        cfg.model.frames,
        cfg.model.channels,
        shape.text_len,
        cfg.model.kf_mode,
        args.steps,
        args.steps - 1
    );
    println!(
        "model FLOPs per step: {:.3} GFLOP = B {} × (MMDiT {:.3} + text encoder {:.3} GFLOP per clip; training = \
         3 × forward)",
        step_flops / 1e9,
        shape.batch,
        mmdit as f64 / 1e9,
        text as f64 / 1e9
    );
    println!(
        "{:<8} {:>11} {:>10} {:>9} {:>10} {:>11} {:>10} {:>8}",
        "backend", "micro_batch", "median_s", "steps/s", "samples/s", "GFLOP/step", "GFLOP/s", "of_peak"
    );
    for &b in &args.backends {
        backend::check(b, precision)?;
        let device = backend::device(b, precision)?;
        let secs = time_rf_steps(cfg, shape, args.steps, &device).with_context(|| format!("backend {b}"))?;
        let step_s = median(&secs[1..]);
        let achieved = step_flops / step_s;
        let of_peak = args
            .peak_tflops
            .map_or_else(|| "-".to_string(), |p| format!("{:.1}%", 100.0 * achieved / (p * 1e12)));
        println!(
            "{:<8} {:>11} {step_s:>10.4} {:>9.3} {:>10.2} {:>11.3} {:>10.2} {of_peak:>8}",
            b.to_string(),
            shape.batch,
            1.0 / step_s,
            shape.batch as f64 / step_s,
            step_flops / 1e9,
            achieved / 1e9
        );
    }
    Ok(ExitCode::SUCCESS)
}

// ---------------------------------------------------------------------------------------------------------------
// VAE presets

/// The same VAE preset for `--steps` steps on each backend through `train_vae`; prints steps/s (median over the
/// steps after the first, which includes start-up).
fn bench_vae(args: &BenchArgs, base: &VaeRunConfig) -> anyhow::Result<ExitCode> {
    let Some(data) = &args.data else {
        bail!(
            "config {}: a VAE preset trains on a store: give --data STORE (`any4d data synth|import`)",
            args.config.display()
        );
    };
    if args.tokens.is_some() || args.peak_tflops.is_some() {
        bail!("--tokens and --peak-tflops apply to RF presets only");
    }
    let runs = tempfile_dir()?;
    println!(
        "backend  steps  median steps/s  median samples/s  wall s   ({})",
        args.config.display()
    );
    for backend in &args.backends {
        let mut cfg = base.clone();
        cfg.device.backend = *backend;
        if let Some(p) = args.precision {
            cfg.device.precision = p;
        }
        if let Some(mb) = args.micro_batch {
            // One micro-batch per step: the step time of that many clips, no accumulation.
            cfg.train.micro_batch = mb;
            cfg.train.batch_size = mb;
        }
        cfg.train.duration = Duration::Steps(args.steps);
        cfg.train.checkpoint_every = args.steps;
        cfg.train.valid_every = args.steps;
        let opts = VaeRunOptions {
            data: data.clone(),
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
            bail!("metrics.csv lacks the throughput columns");
        };
        let median_of = |c: usize| {
            let v: Vec<f64> = table.rows.iter().skip(1).map(|r| r.1[c]).collect();
            if v.is_empty() { f64::NAN } else { median(&v) }
        };
        println!(
            "{:<8} {:>5}  {:>14.3}  {:>16.2}  {wall:>6.1}",
            backend.to_string(),
            args.steps,
            median_of(sps),
            median_of(xps)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rf_steps_run_and_are_timed() {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/rf/tiny.toml"));
        let Preset::Rf(cfg) = Preset::load(path).expect("the tiny RF preset loads") else {
            panic!("configs/rf/tiny.toml is not detected as an RF preset");
        };
        let shape = RfShape {
            batch: 2,
            tokens: 8,
            text_len: cfg.text.max_len,
        };
        let secs = time_rf_steps(&cfg, shape, 2, &Device::flex()).expect("steps run");
        assert_eq!(secs.len(), 2);
        assert!(secs.iter().all(|&s| s > 0.0), "{secs:?}");
    }

    #[test]
    fn presets_are_told_apart_and_others_are_refused() {
        let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
        assert!(matches!(
            Preset::load(&root.join("configs/vae/tiny.toml")),
            Ok(Preset::Vae(_))
        ));
        let tmp = tempfile::tempdir().expect("temp dir");
        let other = tmp.path().join("other.toml");
        std::fs::write(&other, "[train]\nseed = 1\n").expect("write");
        let err = Preset::load(&other).err().expect("neither RF nor VAE").to_string();
        assert!(err.contains("other.toml") && err.contains("neither an RF"), "{err}");
    }
}
