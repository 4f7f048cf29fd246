//! Rectified-flow training (SPEC §4.4–4.7; issue 5 item 1): `any4d train rf`. This file holds the run config
//! (`configs/rf/*.toml`: `[model]` from the model crate, `[rf]` objective options, `[train]`, `[optim]`,
//! `[device]`). The loop itself (frozen-VAE encoding, §3.4 standardisation, §4.5 keyframe masks, text dropout)
//! is not written yet: `train_rf` returns an error saying so.

use std::path::{Path, PathBuf};

use any4d_model::mmdit::MmditConfig;
use any4d_model::rectified_flow::{KeyframeLoss, TauSampler};
use serde::{Deserialize, Serialize};

use crate::config::{DeviceConfig, OptimConfig, TrainConfig, parse_strict, to_toml};
use crate::error::{Result, TrainError, io_err};

/// How the keyframe set of a training sample is drawn (SPEC §4.5, §5.4, §8 X3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KfSampler {
    /// k ~ Unif{0..=k_max}, a uniform k-subset of the T frames (paper, k_max = 5).
    Random,
    /// SceneMI: k ~ Unif{2..T}, first and last always included.
    Scenemi,
}

/// Which VAE latent trains the RF (SPEC §3.4: statistics over posterior samples).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentDraw {
    /// z = μ + σξ, a fresh posterior sample each time a clip is encoded.
    Sample,
    /// z = μ.
    Mean,
}

/// The `[rf]` table: options of the RF objective.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfSection {
    /// Keyframe sampler in training.
    pub kf_sampler: KfSampler,
    /// Largest k of the random sampler (SPEC §4.5: 5).
    pub k_max: usize,
    /// τ distribution (SPEC §4.5 step 4: uniform; AAM: cosmap).
    pub tau_sampler: TauSampler,
    /// Which slots enter (R5) (SPEC §4.2: all).
    pub keyframe_loss: KeyframeLoss,
    /// τ* of (R9) for `kf_mode = "impute_until"` (SPEC §5.4: 0.98).
    pub tau_star: f64,
    /// Std of the keyframe vertex noise per unit l ~ U(0, 1) for `impute_until` (SPEC §5.4: 0.02).
    pub keyframe_noise: f64,
    /// Probability of dropping the caption for CFG (SPEC §4.4: 0.1).
    pub text_dropout: f64,
    /// Posterior sample or mean as the RF's target latent.
    pub latent: LatentDraw,
}

/// A whole `configs/rf/*.toml` run config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfRunConfig {
    /// `[model]`: the MMDiT (strict serde struct of the model crate).
    pub model: MmditConfig,
    /// `[rf]`.
    pub rf: RfSection,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

impl RfRunConfig {
    /// Parses and validates an RF run config; unknown or missing keys anywhere are errors naming `file`.
    pub fn parse(text: &str, file: &Path) -> Result<Self> {
        let cfg: RfRunConfig = parse_strict(text, file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason,
        };
        cfg.model.validate().map_err(bad)?;
        cfg.train.validate(file)?;
        cfg.optim.validate(file)?;
        let rf = &cfg.rf;
        if !(0.0..=1.0).contains(&rf.text_dropout) {
            return Err(bad(format!("rf.text_dropout {} is outside [0, 1]", rf.text_dropout)));
        }
        if !(0.0..=1.0).contains(&rf.tau_star) {
            return Err(bad(format!("rf.tau_star {} is outside [0, 1]", rf.tau_star)));
        }
        if rf.keyframe_noise < 0.0 {
            return Err(bad(format!("rf.keyframe_noise {} is negative", rf.keyframe_noise)));
        }
        if rf.k_max > cfg.model.frames {
            return Err(bad(format!(
                "rf.k_max {} exceeds model.frames {}",
                rf.k_max, cfg.model.frames
            )));
        }
        Ok(cfg)
    }

    /// Reads a config file.
    pub fn load(file: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(file).map_err(io_err("read config", file))?;
        Self::parse(&text, file)
    }

    /// The fully resolved config as TOML.
    pub fn to_toml(&self) -> Result<String> {
        to_toml(self)
    }
}

/// Options of `any4d train rf` besides the config.
pub struct RfRunOptions {
    /// Store folder (`--data`).
    pub data: PathBuf,
    /// The frozen VAE's run folder (`--vae`).
    pub vae_run: PathBuf,
    /// Folder that holds run folders.
    pub runs_dir: PathBuf,
    /// Run name.
    pub name: String,
}

/// RF training entry point. Not implemented yet.
pub fn train_rf(_cfg: &RfRunConfig, _opts: &RfRunOptions) -> Result<()> {
    Err(TrainError::Other(
        "RF training is not implemented yet (train/src/rf_loop.rs holds only its config so far)".into(),
    ))
}
