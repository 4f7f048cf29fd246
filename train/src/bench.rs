//! What `any4d bench train` measures: the training throughput of a run preset on a backend. An RF preset times the
//! RF training step at the preset's size on random standardised latents — no VAE run and no store needed — with its
//! analytic model FLOPs; a VAE preset trains on a store through [`train_vae`], a BD-LSTM preset through
//! [`train_bdlstm`] (on a VAE's latents or, the ACAP variant, on the store's vertices), and each reads the throughput
//! from its run's `metrics.csv`. `any4d bench store` times the streaming reader: a store read in a training epoch's
//! order.

use std::path::{Path, PathBuf};
use std::time::Instant;

use any4d_model::bench::median;
use any4d_model::rectified_flow::{RfBatch, rf_training_loss};
use burn::optim::GradientsParams;
use burn::prelude::{Bool, Device, Int, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::bdlstm::train_bdlstm;
use crate::bdlstm_loop::{BdlstmRunConfig, BdlstmRunOptions};
use any4d_data::store::Store;

use crate::config::{Duration, TrainConfig};
use crate::data_order::DataOrder;
use crate::error::{Result, TrainError};
use crate::grad_clip::clip_global_norm;
use crate::loop_common::{FlushScope, RunOptions, StopFlag, scalar, step_seed};
use crate::progress::ProgressMode;
use crate::rf_loop::{RfRunConfig, training_mask};
use crate::run_folder::{METRICS_FILE, RunFolder, read_table};
use crate::vae_loop::{VaeRunConfig, train_vae};

/// Sizes of the timed RF batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RfShape {
    /// Clips per step B.
    pub batch: usize,
    /// FPS tokens P.
    pub tokens: usize,
    /// Caption tokens L (`text.max_len`).
    pub text_len: usize,
}

/// Model FLOPs of one RF training step at `shape` (3 × forward, MMDiT plus caption encoder), and the two parts per
/// clip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RfStepFlops {
    /// FLOPs of the whole step (B clips).
    pub step: f64,
    /// MMDiT training FLOPs per clip.
    pub mmdit_per_clip: u64,
    /// Caption-encoder training FLOPs per clip.
    pub text_per_clip: u64,
}

/// The analytic FLOPs of an RF training step of `cfg` at `shape`.
pub fn rf_step_flops(cfg: &RfRunConfig, shape: RfShape) -> RfStepFlops {
    let mmdit = cfg.model.forward_flops(shape.tokens, shape.text_len).training_step();
    let text = cfg
        .model_config(cfg.text.vocab_size)
        .text
        .forward_flops()
        .training_step();
    RfStepFlops {
        step: (mmdit + text) as f64 * shape.batch as f64,
        mmdit_per_clip: mmdit,
        text_per_clip: text,
    }
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

/// Random standardised latents z₀ `[B, P, C]` and Z `[B, P, T, C]` ~ N(0, I) (what docs/method.md §3.4's
/// standardisation aims at), keyframe masks from [`training_mask`], uniform token ids without padding, keep_txt with
/// the preset's CFG dropout, ε and τ as in training. Host draws from `rng`, the rest from the device stream.
fn rf_inputs(cfg: &RfRunConfig, shape: RfShape, rng: &mut ChaCha8Rng, device: &Device) -> RfInputs {
    let RfShape {
        batch: b,
        tokens: p,
        text_len: l,
    } = shape;
    let (t, c) = (cfg.model.frames, cfg.model.channels);
    let normal = Distribution::Normal(0.0, 1.0);
    let mask: Vec<f32> = (0..b)
        .flat_map(|_| training_mask(&cfg.rf, cfg.model.conditioning, t, rng))
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

/// Seconds of each of `steps` RF training steps on `device` (the first is the warm-up): caption encoder forward,
/// (R5) through [`rf_training_loss`] as the RF objective computes it, backward, global-norm clipping and the AdamW
/// step of the training loop, then a device sync. The model is built at the preset's size with the preset's largest
/// vocabulary; `impute_until` uses Z as its keyframe latents (the VAE encoding of noisy keyframes is not timed).
/// Subnormals are flushed as the training loop flushes them (`train.flush_denormals`, docs/method.md §10).
pub fn time_rf_steps(cfg: &RfRunConfig, shape: RfShape, steps: u64, device: &Device) -> Result<Vec<f64>> {
    let _flush = cfg.train.flush_denormals.then(FlushScope::begin);
    let ad = device.clone().autodiff();
    ad.seed(cfg.train.seed);
    let mut model = cfg.model_config(cfg.text.vocab_size).init(&ad);
    let mut optim = cfg.optim.init();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.train.seed);
    let loss_options = cfg.loss_options();
    let sync = |what: &str| {
        ad.sync()
            .map_err(|e| TrainError::Devices(format!("device sync {what}: {e:?}")))
    };
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
            scene: None,
        };
        let loss = rf_training_loss(&model.mmdit, &batch, x.eps, x.tau, &loss_options); // (R5)
        let value = scalar(loss.clone());
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let (grads, norm) = clip_global_norm(&model, grads, cfg.optim.grad_clip);
        model = optim.step(cfg.optim.lr, model, grads);
        sync("after the step")?;
        secs.push(start.elapsed().as_secs_f64());
        if !(value.is_finite() && norm.is_finite()) {
            return Err(TrainError::NonFinite {
                step,
                what: format!("loss {value} or gradient norm {norm}"),
                value: if value.is_finite() { norm } else { value },
                last_good: None,
            });
        }
    }
    Ok(secs)
}

/// Throughput of a trained preset (VAE or BD-LSTM): medians over the steps after the first (which includes start-up).
#[derive(Clone, Debug, PartialEq)]
pub struct TrainThroughput {
    /// Median optimiser steps per second.
    pub steps_per_s: f64,
    /// Median clips per second.
    pub samples_per_s: f64,
    /// Wall seconds of the whole run, start-up and validation included.
    pub wall_s: f64,
    /// The run folder it wrote.
    pub run: PathBuf,
}

/// Trains `cfg` for `steps` steps on the store `data` into a run named `name` under `runs_dir` (checkpoints and
/// validation only at the end) and reads its throughput from `metrics.csv`.
pub fn time_vae_steps(
    mut cfg: VaeRunConfig,
    data: &Path,
    steps: u64,
    runs_dir: &Path,
    name: &str,
) -> Result<TrainThroughput> {
    steps_only(&mut cfg.train, steps);
    timed(quiet_run(data, runs_dir, name), |run| Ok(train_vae(&cfg, &run)?.0))
}

/// [`time_vae_steps`] for a BD-LSTM preset: the latent variant on the frozen VAE of `vae_run`, the ACAP variant
/// (`vae_run` = `None`) on the features of the store's single topology.
pub fn time_bdlstm_steps(
    mut cfg: BdlstmRunConfig,
    data: &Path,
    vae_run: Option<&Path>,
    steps: u64,
    runs_dir: &Path,
    name: &str,
) -> Result<TrainThroughput> {
    steps_only(&mut cfg.train, steps);
    timed(quiet_run(data, runs_dir, name), |run| {
        let vae_run = vae_run.map(Path::to_path_buf);
        Ok(train_bdlstm(&cfg, &BdlstmRunOptions { run, vae_run })?.0)
    })
}

/// Runs `train` with `run` and reads the throughput of the run folder it wrote, with the wall time of the call.
fn timed(run: RunOptions, train: impl FnOnce(RunOptions) -> Result<RunFolder>) -> Result<TrainThroughput> {
    let t0 = Instant::now();
    let folder = train(run)?;
    throughput(folder.root(), t0.elapsed().as_secs_f64())
}

/// `steps` steps, with the checkpoint and the validation only at the end.
fn steps_only(train: &mut TrainConfig, steps: u64) {
    train.duration = Duration::Steps(steps);
    train.checkpoint_every = steps;
    train.valid_every = steps;
}

fn quiet_run(data: &Path, runs_dir: &Path, name: &str) -> RunOptions {
    RunOptions {
        data: data.to_path_buf(),
        runs_dir: runs_dir.to_path_buf(),
        name: name.to_string(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
        parallel: None,
    }
}

/// The medians of `metrics.csv` in `run` (rows after the first).
fn throughput(run: &Path, wall_s: f64) -> Result<TrainThroughput> {
    let table = read_table(&run.join(METRICS_FILE))?;
    let col = |name: &str| table.header.iter().position(|h| h == name).map(|i| i - 1);
    let (Some(sps), Some(xps)) = (col("steps_per_s"), col("samples_per_s")) else {
        return Err(crate::error::run_err(run, "metrics.csv lacks the throughput columns"));
    };
    let median_of = |c: usize| median(&table.rows.iter().skip(1).map(|r| r.1[c]).collect::<Vec<_>>());
    Ok(TrainThroughput {
        steps_per_s: median_of(sps),
        samples_per_s: median_of(xps),
        wall_s,
        run: run.to_path_buf(),
    })
}

/// Ours — the keyframe RF with its frame-wise VAE and scratch caption encoder — at the sizes of the run configs `rf`
/// and `vae`, with freshly initialised weights (seeded): what timing P-Table 4 needs on a machine that has no trained
/// run (the work per clip does not depend on the weights). Latent statistics are the identity; the sampler is the
/// paper's midpoint solver on an `n_grid`-point grid (`any4d bench sample`).
pub fn untrained_keyframe_method(
    rf: &RfRunConfig,
    vae: &VaeRunConfig,
    n_grid: usize,
    device: &Device,
) -> Result<Box<dyn any4d_eval::methods::Method>> {
    use std::sync::Arc;

    use any4d_data::batch::PadTo;
    use any4d_eval::learned::{LearnedModels, MeshCodec, RfSampler};
    use any4d_eval::methods::{MethodKind, RfMethod};
    use any4d_model::any_vae::{AnyMeshVae, AnyMeshVaeConfig};
    use any4d_model::latent_stats::LatentStats;
    use any4d_model::mmdit::KeyframeConditioning;
    use any4d_model::rectified_flow::SampleOptions;
    use any4d_model::text::scratch::{ScratchTextEncoder, ScratchTokenizer};

    let setup = |reason: String| TrainError::Setup(format!("bench sample: {reason}"));
    let AnyMeshVaeConfig::Framewise(vae_model) = &vae.model else {
        return Err(setup(
            "the VAE config must be frame-wise (vae.kind = \"framewise\")".into(),
        ));
    };
    if rf.model.conditioning != KeyframeConditioning::InputMask {
        return Err(setup(format!(
            "times ours: the RF config needs model.conditioning = \"input_mask\", got {:?}",
            rf.model.conditioning
        )));
    }
    if rf.model.channels != vae_model.body.latent_channels {
        return Err(setup(format!(
            "model.channels = {} of the RF config differs from the VAE config's latent_channels = {}",
            rf.model.channels, vae_model.body.latent_channels
        )));
    }
    if n_grid < 2 {
        return Err(setup(format!("--n-grid {n_grid}: needs at least 2 grid points")));
    }
    device.seed(rf.train.seed);
    let captions = ["a waving sheet", "a small sphere spins", "a dog walks slowly"].map(String::from);
    let tokenizer = ScratchTokenizer::train(&captions, rf.text.vocab_size)?;
    let network = rf.model_config(tokenizer.vocab_size()).init(device);
    let text = ScratchTextEncoder {
        tokenizer,
        model: network.text,
    };
    let codec = MeshCodec::new(
        AnyMeshVae::Framewise(vae_model.init(device)),
        vae.vae.tokens,
        PadTo::BatchMax,
        device.clone(),
    )?;
    let identity = LatentStats {
        shape_mean: 0.0,
        shape_std: 1.0,
        motion_mean: 0.0,
        motion_std: 1.0,
    };
    let models = LearnedModels::new(
        Arc::new(codec),
        network.mmdit,
        rf.model.clone(),
        identity,
        Box::new(text),
    )?;
    let options = SampleOptions {
        n_grid,
        ..SampleOptions::paper(KeyframeConditioning::InputMask)
    };
    let sampler = RfSampler::for_method(MethodKind::KeyframeRf, Arc::new(models), options, 1.0)?;
    Ok(Box::new(RfMethod::new(MethodKind::KeyframeRf, sampler)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run_config::RunConfig;

    fn root() -> &'static Path {
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
    }

    #[test]
    fn rf_steps_run_and_are_timed() {
        let RunConfig::Rf(cfg) = RunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).expect("loads") else {
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
        let flops = rf_step_flops(&cfg, shape);
        assert_eq!(flops.step, 2.0 * (flops.mmdit_per_clip + flops.text_per_clip) as f64);
    }

    #[test]
    fn presets_are_told_apart_and_others_are_refused() {
        assert!(matches!(
            RunConfig::load(&root().join("configs/vae/tiny.toml"), &[]),
            Ok(RunConfig::Vae(_))
        ));
        let tmp = tempfile::tempdir().expect("temp dir");
        let other = tmp.path().join("other.toml");
        std::fs::write(&other, "[train]\nseed = 1\n").expect("write");
        let err = RunConfig::load(&other, &[])
            .expect_err("neither RF nor VAE")
            .to_string();
        assert!(err.contains("other.toml") && err.contains("neither an RF"), "{err}");
    }
}

/// What [`time_store_read`] measured.
#[derive(Clone, Debug, PartialEq)]
pub struct StoreRead {
    /// Clips read and decoded.
    pub clips: usize,
    /// Bytes of their records.
    pub bytes: u64,
    /// Wall seconds.
    pub seconds: f64,
}

/// Reads and decodes the first `limit` clips (all with `None`) of `store` in the order a training epoch visits them
/// on it ([`DataOrder::sharded`]: shard by shard through a shuffle buffer of `buffer` examples, from `seed`), as the
/// streaming reader of training does: one clip at a time on the calling thread.
pub fn time_store_read(store: &Store, seed: u64, buffer: usize, limit: Option<usize>) -> Result<StoreRead> {
    if store.is_empty() {
        return Err(TrainError::Setup(format!(
            "store {} holds no clip",
            store.dir().display()
        )));
    }
    let blocks: Vec<usize> = (0..store.shard_count()).map(|k| store.shard_range(k).len()).collect();
    let mut order = DataOrder::sharded(seed, &blocks, buffer);
    let clips = limit.unwrap_or(store.len()).clamp(1, store.len());
    let start = Instant::now();
    let mut bytes = 0;
    for i in order.take(clips) {
        std::hint::black_box(store.get(i)?);
        bytes += store.record_bytes(i)?;
    }
    Ok(StoreRead {
        clips,
        bytes,
        seconds: start.elapsed().as_secs_f64(),
    })
}
