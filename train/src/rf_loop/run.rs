//! `any4d train rf`: new runs and `--resume`, on one device or data-parallel.

use std::path::{Path, PathBuf};

use any4d_data::store::{Split, Store};
use any4d_model::mmdit::Anchor;
use any4d_model::text::scratch::ScratchTokenizer;
use burn::prelude::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::backend;
use crate::error::{Result, TrainError};
use crate::loop_common::{self, LoopSetup, Objective, Outcome, RunOptions};
use crate::multi_device::{run_strategy, strategy_note, train_data_parallel, worker_devices};
use crate::run_folder::{RunFolder, open_for_resume};
use crate::runs::{self, LoadedVae, VaeRunRecord};

use super::RF_TERMS;
use super::batcher::{check_compatible, open_store};
use super::config::RfRunConfig;
use super::objective::RfObjective;

/// Options of `any4d train rf` besides the config: those of every run, and the frozen VAE.
pub struct RfRunOptions {
    /// Data, run folder, progress, stop flag, devices.
    pub run: RunOptions,
    /// The frozen VAE's run folder (`--vae`): required for a new run; for `--resume` it may be omitted (the run
    /// folder records it) and must otherwise name the same run.
    pub vae_run: Option<PathBuf>,
}

/// Starts a new RF run with `cfg` on the frozen VAE of `opts.vae_run`; returns the run folder and the outcome.
/// The run folder gets `vae_run.json` (which VAE run and checkpoint step) and `tokenizer.json`.
pub fn train_rf(cfg: &RfRunConfig, opts: &RfRunOptions) -> Result<(RunFolder, Outcome)> {
    let vae_dir = opts
        .vae_run
        .as_deref()
        .ok_or_else(|| TrainError::Setup("a new RF run needs the VAE run folder (--vae RUN)".into()))?;
    // Fail before claiming a run folder when the backend, the store or the VAE run is unusable.
    let devices = worker_devices(&cfg.device, &cfg.train, opts.run.parallel.as_ref())?;
    let store = open_store(&opts.run.data)?;
    let vae = runs::load_vae_run(vae_dir, &devices[0])?;
    check_compatible(cfg, &store, &vae)?;
    let captions = train_captions(&store)?;
    let tokenizer = ScratchTokenizer::train(&captions, cfg.text.vocab_size)?;

    let run = RunFolder::create(&opts.run.runs_dir, &opts.run.name, &cfg.to_toml()?, &RF_TERMS)?;
    runs::write_vae_record(&run, &VaeRunRecord::of(&vae)?)?;
    tokenizer.save(run.root())?;
    run.log(&format!(
        "tokenizer trained on {} TRAIN captions: {} tokens",
        captions.len(),
        tokenizer.vocab_size()
    ))?;
    let outcome = run_rf(cfg, &run, opts, &vae, tokenizer, &devices, None)?;
    Ok((run, outcome))
}

/// Continues the RF run in `run_dir` from its newest checkpoint (config, tokenizer and VAE run from the run
/// folder; the backend may be overridden).
pub fn resume_rf(run_dir: &Path, backend: Option<backend::Backend>, opts: &RfRunOptions) -> Result<Outcome> {
    let (run, cfg, ckpt) = open_for_resume(run_dir, RfRunConfig::parse, backend, |c: &mut RfRunConfig| {
        &mut c.device
    })?;
    let record = runs::recorded_vae(run_dir, opts.vae_run.as_deref())?;
    let devices = worker_devices(&cfg.device, &cfg.train, opts.run.parallel.as_ref())?;
    let vae = record.load(&devices[0])?;
    let tokenizer = ScratchTokenizer::load(run_dir)?;
    run_rf(&cfg, &run, opts, &vae, tokenizer, &devices, Some(ckpt))
}

fn train_captions(store: &Store) -> Result<Vec<String>> {
    store
        .indices(Split::Train)
        .into_iter()
        .map(|i| Ok(store.get(i)?.clip.caption))
        .collect()
}

fn run_rf(
    cfg: &RfRunConfig,
    run: &RunFolder,
    opts: &RfRunOptions,
    vae: &LoadedVae,
    tokenizer: ScratchTokenizer,
    devices: &[Device],
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    let vocab = tokenizer.vocab_size();
    let mut objective = RfObjective::new(cfg, &opts.run.data, vae, tokenizer, &devices[0])?;
    objective.log_validation_samples(run)?;
    if let Anchor::KeyframeLerp { scale } = cfg.model.anchor {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.train.seed);
        let clips = cfg.train.batch_size;
        if let Some(rms) = objective.batcher().anchor_residual_rms(clips, &mut rng, &devices[0]) {
            run.log(&format!(
                "anchor: Z − A has RMS {rms:.4} on the generated slots of the first {clips} TRAIN windows \
                 (standardized posterior means); model.anchor scale s = {scale}"
            ))?;
        }
    }
    run.log(&format!(
        "RF {:?} on {} ({} train clips in {} windows / {} val clips, latents {:?}: {:.1} MiB), VAE {} step {}, backend {}",
        cfg.model.conditioning,
        opts.run.data.display(),
        objective.train_len(),
        objective.train_windows(),
        objective.valid_len(),
        cfg.rf.latent_cache,
        objective.cached_bytes() as f64 / (1024.0 * 1024.0),
        vae.run.display(),
        vae.step,
        cfg.device.backend
    ))?;
    let ad: Vec<Device> = devices.iter().map(|d| d.clone().autodiff()).collect();
    ad[0].seed(cfg.train.seed);
    let model = cfg.model_config(vocab).init(&ad[0]);
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: ad[0].clone(),
        stop: opts.run.stop.clone(),
        progress: opts.run.progress,
        resume,
    };
    let parallel = opts.run.parallel.as_ref();
    let (_, outcome) = match run_strategy(devices, parallel) {
        Some(strategy) => {
            run.log(&strategy_note(devices, parallel, strategy))?;
            train_data_parallel(&objective, model, setup, &ad, strategy)?
        }
        None => loop_common::train(&objective, model, setup)?,
    };
    Ok(outcome)
}
