//! Loading trained runs for evaluation, sampling and the quickstart: a VAE run (its resolved config,
//! newest checkpoint and the docs/method.md §3.4 latent statistics of that checkpoint) and an RF run (config, newest
//! checkpoint, the scratch tokenizer and the record of the VAE run it was trained on). Errors name the run folder
//! and the missing or bad file.

use std::path::{Path, PathBuf};

use any4d_data::io::write_atomic;
use any4d_model::any_vae::{AnyMeshVae, AnyMeshVaeConfig};
use any4d_model::frame_vae::FrameVae;
use any4d_model::latent_stats::LatentStats;
use any4d_model::text::scratch::{ScratchTokenizer, TOKENIZER_FILE};
use burn::prelude::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::checkpoint;
use crate::error::{Result, TrainError, io_err, run_err};
use crate::rf_loop::{RfModel, RfRunConfig};
use crate::run_folder::{CHECKPOINTS_DIR, CONFIG_FILE, RunFolder};
use crate::vae_loop::{LATENT_STATS_FILE, StoredLatentStats, VaeRunConfig};

/// File in an RF run folder naming the VAE run (and its checkpoint step) whose latents trained it.
pub const VAE_RUN_FILE: &str = "vae_run.json";

/// A VAE run ready for encoding and decoding.
#[derive(Debug, Clone)]
pub struct LoadedVae {
    /// The network with the newest checkpoint's parameters.
    pub model: AnyMeshVae,
    /// docs/method.md §3.4 statistics of that checkpoint.
    pub stats: LatentStats,
    /// The run's resolved config.
    pub config: VaeRunConfig,
    /// The run folder (canonical path).
    pub run: PathBuf,
    /// The checkpoint folder loaded.
    pub checkpoint: PathBuf,
    /// Its step.
    pub step: u64,
}

impl LoadedVae {
    /// The frame-wise VAE, or an error naming the run when it is the sequence-wise ablation.
    pub fn frame_vae(&self) -> Result<&FrameVae> {
        match &self.model {
            AnyMeshVae::Framewise(m) => Ok(m),
            AnyMeshVae::Sequencewise(_) => Err(run_err(
                &self.run,
                "a sequence-wise DyMeshVAE; the keyframe RF needs a frame-wise VAE (vae.kind = \"framewise\")",
            )),
        }
    }

    /// Refuses a store whose clips hold fewer FPS tokens than this frame-wise VAE encodes (or a sequence-wise VAE):
    /// what every model trained on its per-frame latents needs.
    pub fn check_store(&self, store: &any4d_data::store::Store) -> Result<()> {
        self.frame_vae()?;
        self.check_store_any_kind(store)
    }

    /// Refuses a store whose clips hold fewer FPS tokens than this VAE encodes, or (sequence-wise VAE) whose clips
    /// are not as long as the trajectories it was built for.
    pub fn check_store_any_kind(&self, store: &any4d_data::store::Store) -> Result<()> {
        if let Some(t) = self.model.clip_frames()
            && t != store.frames()
        {
            return Err(TrainError::Setup(format!(
                "the sequence-wise VAE run {} encodes {t}-frame clips, the store {} holds {}-frame clips",
                self.run.display(),
                store.dir().display(),
                store.frames()
            )));
        }
        if self.tokens() > store.p() {
            return Err(TrainError::Setup(format!(
                "the VAE run {} encodes P = {} FPS tokens, the store {} holds {}: import it with --p {} or more",
                self.run.display(),
                self.tokens(),
                store.dir().display(),
                store.p(),
                self.tokens()
            )));
        }
        Ok(())
    }

    /// FPS tokens P the VAE encodes (`vae.tokens`).
    pub fn tokens(&self) -> usize {
        self.config.vae.tokens
    }

    /// Latent channels C per slot.
    pub fn latent_channels(&self) -> usize {
        self.config.model.latent_channels()
    }
}

fn missing(run: &Path, file: &str, hint: &str) -> TrainError {
    run_err(run, format!("`{file}` is missing{hint}"))
}

fn canonical(run_dir: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(run_dir).map_err(io_err("open run folder", run_dir))
}

fn read_run_file(run: &Path, file: &str, hint: &str) -> Result<String> {
    let p = run.join(file);
    if !p.is_file() {
        return Err(missing(run, file, hint));
    }
    std::fs::read_to_string(&p).map_err(io_err("read", p))
}

/// The newest complete checkpoint of a run and its step.
pub(crate) fn newest_checkpoint(run: &Path) -> Result<(PathBuf, u64)> {
    let dir = run.join(CHECKPOINTS_DIR);
    if !dir.is_dir() {
        return Err(missing(run, CHECKPOINTS_DIR, " (not a run folder?)"));
    }
    let ckpt = checkpoint::latest(&dir)?.ok_or_else(|| TrainError::Checkpoint {
        path: dir.clone(),
        reason: format!("run {} has no complete checkpoint yet", run.display()),
    })?;
    let step = checkpoint::read_state(&ckpt)?.step;
    Ok((ckpt, step))
}

/// Loads a VAE run onto `device`: `config.toml`, the newest checkpoint and `latent_stats.json`, which must belong
/// to that checkpoint (a run that was stopped or continued has none, or stale ones).
pub fn load_vae_run(run_dir: &Path, device: &Device) -> Result<LoadedVae> {
    let run = canonical(run_dir)?;
    let config = VaeRunConfig::parse(
        &read_run_file(&run, CONFIG_FILE, " (not a VAE run folder?)")?,
        &run.join(CONFIG_FILE),
    )?;
    let (ckpt, step) = newest_checkpoint(&run)?;
    let stats_text = read_run_file(
        &run,
        LATENT_STATS_FILE,
        " (written when a VAE run finishes: finish it with `any4d train vae --resume`)",
    )?;
    let stored: StoredLatentStats =
        serde_json::from_str(&stats_text).map_err(|e| run_err(&run, format!("bad `{LATENT_STATS_FILE}`: {e}")))?;
    if stored.step != step {
        return Err(run_err(
            &run,
            format!(
                "`{LATENT_STATS_FILE}` belongs to step {}, the newest checkpoint is step {step}; finish the run so \
                 that its statistics are recomputed",
                stored.step
            ),
        ));
    }
    let model = match &config.model {
        AnyMeshVaeConfig::Framewise(c) => {
            AnyMeshVae::Framewise(checkpoint::load_for_sampling(c.init(device), &ckpt)?.0)
        }
        AnyMeshVaeConfig::Sequencewise(c) => {
            AnyMeshVae::Sequencewise(checkpoint::load_for_sampling(c.init(device), &ckpt)?.0)
        }
    };
    Ok(LoadedVae {
        model,
        stats: stored.stats,
        config,
        run,
        checkpoint: ckpt,
        step,
    })
}

/// `vae_run.json` of an RF run: the VAE run folder (canonical path) and the checkpoint step whose latents and
/// statistics trained the RF.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VaeRunRecord {
    /// The VAE run folder.
    pub run: PathBuf,
    /// Its checkpoint step.
    pub step: u64,
}

impl VaeRunRecord {
    /// The record of a loaded VAE.
    pub fn of(vae: &LoadedVae) -> Result<Self> {
        Ok(Self {
            run: vae.run.clone(),
            step: vae.step,
        })
    }

    /// Loads the recorded VAE run; errors if its newest checkpoint is no longer the recorded step.
    pub fn load(&self, device: &Device) -> Result<LoadedVae> {
        let vae = load_vae_run(&self.run, device)?;
        if vae.step != self.step {
            return Err(run_err(
                &self.run,
                format!(
                    "now at step {}, but the RF was trained on its step {}: its latents changed",
                    vae.step, self.step
                ),
            ));
        }
        Ok(vae)
    }
}

/// Writes `vae_run.json` into an RF run folder.
pub fn write_vae_record(run: &RunFolder, record: &VaeRunRecord) -> Result<()> {
    let json =
        serde_json::to_vec_pretty(record).map_err(|e| run_err(run.root(), format!("serialise {VAE_RUN_FILE}: {e}")))?;
    Ok(write_atomic(&run.path(VAE_RUN_FILE), &json)?)
}

/// Reads `vae_run.json` of the RF run in `run_dir`. A relative `run` is resolved against `run_dir`, so run folders
/// shipped side by side (`weights/small/rf` naming `../vae`) load from wherever the repository is cloned.
pub fn read_vae_record(run_dir: &Path) -> Result<VaeRunRecord> {
    let text = read_run_file(run_dir, VAE_RUN_FILE, " (not an RF run folder?)")?;
    let mut record: VaeRunRecord =
        serde_json::from_str(&text).map_err(|e| run_err(run_dir, format!("bad `{VAE_RUN_FILE}`: {e}")))?;
    if record.run.is_relative() {
        let joined = run_dir.join(&record.run);
        record.run = std::fs::canonicalize(&joined).unwrap_or(joined);
    }
    Ok(record)
}

/// The VAE record of the run in `run_dir` (an RF or BD-LSTM run) for `--resume`; a `given` `--vae` must name the
/// same run folder.
pub fn recorded_vae(run_dir: &Path, given: Option<&Path>) -> Result<VaeRunRecord> {
    let record = read_vae_record(run_dir)?;
    if let Some(given) = given {
        let given = std::fs::canonicalize(given).map_err(io_err("resolve VAE run folder", given))?;
        if given != record.run {
            return Err(TrainError::Setup(format!(
                "--vae {} differs from the VAE run {} that {} was trained on",
                given.display(),
                record.run.display(),
                run_dir.display()
            )));
        }
    }
    Ok(record)
}

/// An RF run ready for sampling.
pub struct LoadedRf {
    /// MMDiT and caption transformer with the newest checkpoint's parameters (the average, docs/method.md §4.8,
    /// when the run keeps one).
    pub model: RfModel,
    /// The caption tokenizer trained at run start.
    pub tokenizer: ScratchTokenizer,
    /// The run's resolved config.
    pub config: RfRunConfig,
    /// The VAE run it was trained on.
    pub vae: VaeRunRecord,
    /// The run folder (canonical path).
    pub run: PathBuf,
    /// The checkpoint folder loaded.
    pub checkpoint: PathBuf,
    /// Its step.
    pub step: u64,
}

impl LoadedRf {
    /// Loads the VAE run this RF was trained on (same checkpoint step, else an error).
    pub fn load_vae(&self, device: &Device) -> Result<LoadedVae> {
        self.vae.load(device)
    }

    /// Caption token states for the MMDiT's text stream.
    ///
    /// # Shapes
    /// - output: `[B, L, D_txt]`, B = `captions.len()`, L = `text.max_len`
    pub fn encode_text(&self, captions: &[String], device: &Device) -> Result<Tensor<3>> {
        self.model
            .encode_text(&self.tokenizer, captions, self.config.text.max_len, device)
    }
}

/// The resolved config of the RF run (or packed folder) `run_dir`.
pub fn read_rf_config(run_dir: &Path) -> Result<RfRunConfig> {
    RfRunConfig::parse(
        &read_run_file(run_dir, CONFIG_FILE, " (not an RF run folder?)")?,
        &run_dir.join(CONFIG_FILE),
    )
}

/// Loads an RF run onto `device`: `config.toml`, `tokenizer.json`, `vae_run.json` and the newest checkpoint.
pub fn load_rf_run(run_dir: &Path, device: &Device) -> Result<LoadedRf> {
    let run = canonical(run_dir)?;
    let config = read_rf_config(&run)?;
    if !run.join(TOKENIZER_FILE).is_file() {
        return Err(missing(&run, TOKENIZER_FILE, " (written when an RF run starts)"));
    }
    let tokenizer = ScratchTokenizer::load(&run)?;
    let vae = read_vae_record(&run)?;
    let (ckpt, step) = newest_checkpoint(&run)?;
    let (model, _) = checkpoint::load_for_sampling(config.model_config(tokenizer.vocab_size()).init(device), &ckpt)?;
    Ok(LoadedRf {
        model,
        tokenizer,
        config,
        vae,
        run,
        checkpoint: ckpt,
        step,
    })
}
