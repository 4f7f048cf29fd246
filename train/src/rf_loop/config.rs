//! `configs/rf/*.toml`: the run config of the keyframe RF (`[model]`, `[rf]`, `[text]`, `[train]`, `[optim]`,
//! `[device]`), parsed strictly.

use std::path::Path;

use any4d_data::augment::Augment;
use any4d_data::keyframes::TrainingKeyframes;
use any4d_model::mmdit::{Anchor, KeyframeConditioning, MmditConfig};
use any4d_model::rectified_flow::{KeyframeLoss, RfLossOptions, TauSampler};
use any4d_model::text::scratch::ScratchTextConfig;
use serde::{Deserialize, Serialize};

use crate::config::resolve;
use crate::config::{DeviceConfig, OptimConfig, TrainConfig, to_toml};
use crate::error::{Result, TrainError};

use super::VALID_SAMPLE_KEYFRAMES;
use super::network::RfModelConfig;

/// Which VAE latent trains the RF (docs/method.md §3.4: statistics over posterior samples).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentDraw {
    /// z = μ + σξ, a fresh posterior sample every time a clip enters a batch.
    Sample,
    /// z = μ.
    Mean,
}

/// Where the frozen-VAE latents live during training.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentCache {
    /// Encode every clip once at run start and keep z₀, μ and log σ² in host memory: P·C·(1 + 2T) floats per clip
    /// (811 KB at the paper's P = 512, C = 12, T = 16, so about 169 GB for 208K clips).
    Memory,
    /// Encode each micro-batch with the frozen VAE when it is drawn: no memory, one VAE forward per batch.
    PerBatch,
    /// Encode every clip once into one file per store shard (`--latents DIR`, or `latents/` in the run folder; files
    /// already current are reused, so shards can be encoded beforehand by separate `any4d train latents --shard K`
    /// processes) and read each batch's latents from disk: no VAE forward per batch and resident memory independent
    /// of the store's size.
    Disk,
}

/// The `[rf]` table: options of the RF objective.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfSection {
    /// Keyframe sampler in training.
    pub kf_sampler: TrainingKeyframes,
    /// Largest k of the random sampler (docs/method.md §4.5: 5).
    pub k_max: usize,
    /// τ distribution (docs/method.md §4.5 step 4: uniform; AAM: cosmap).
    pub tau_sampler: TauSampler,
    /// Which slots enter (R5) (docs/method.md §4.2: all).
    pub keyframe_loss: KeyframeLoss,
    /// τ* of (R9) for `conditioning = "impute_until"` (docs/method.md §5.4: 0.98).
    pub tau_star: f64,
    /// Std of the keyframe vertex noise per unit l ~ U(0, 1) for `impute_until` (docs/method.md §5.4: 0.02).
    pub keyframe_noise: f64,
    /// Probability of dropping the caption for CFG (docs/method.md §4.4: 0.1).
    pub text_dropout: f64,
    /// Posterior sample or mean as the RF's target latent.
    pub latent: LatentDraw,
    /// Frozen-VAE latents cached in memory or encoded per batch.
    pub latent_cache: LatentCache,
    /// Validation sampling at every validation whose step is a multiple of this, and at the
    /// last step; 0 = off. A multiple of `train.valid_every`.
    pub valid_sample_every: u64,
    /// VAL clips sampled (the first ones in store order, the same every time).
    pub valid_sample_clips: usize,
    /// Grid points over [0, 1] of the validation sampler (docs/method.md §4.6: 64, midpoint solver).
    pub valid_sample_grid: usize,
    /// Training-time augmentation of each example before the frozen VAE encodes it (docs/method.md §2.9); needs
    /// `latent_cache = "per_batch"` (cached latents are of the stored clips). Off when absent, as in the paper
    /// presets.
    #[serde(default, skip_serializing_if = "Augment::is_off")]
    pub augment: Augment,
}

/// Which caption encoder the RF trains with (docs/method.md §4.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextEncoderKind {
    /// WordPiece tokenizer trained on the TRAIN captions + a small transformer trained jointly with the RF.
    /// (The CLIP and BERT loaders of the model crate are not wired into training yet.)
    Scratch,
}

/// The `[text]` table: the caption encoder. Its width is `model.text_dim`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextSection {
    /// Encoder kind.
    pub encoder: TextEncoderKind,
    /// Largest tokenizer vocabulary (special tokens included); the trained one may be smaller.
    pub vocab_size: usize,
    /// Transformer layers.
    pub layers: usize,
    /// Attention heads; must divide `model.text_dim`.
    pub heads: usize,
    /// Tokens L per caption (docs/method.md §1.1: 77).
    pub max_len: usize,
}

/// A whole `configs/rf/*.toml` run config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfRunConfig {
    /// `[model]`: the MMDiT (strict serde struct of the model crate).
    pub model: MmditConfig,
    /// `[rf]`.
    pub rf: RfSection,
    /// `[text]`.
    pub text: TextSection,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

impl RfRunConfig {
    /// Parses and validates a resolved RF run config; unknown or missing keys anywhere are errors naming `file` and
    /// the dotted key.
    pub fn from_table(table: toml::Table, file: &Path) -> Result<Self> {
        let cfg: RfRunConfig = resolve::from_table(table, file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason,
        };
        cfg.model.validate().map_err(bad)?;
        cfg.train.validate(file)?;
        cfg.optim.validate(file)?;
        let rf = &cfg.rf;
        rf.tau_sampler.validate().map_err(bad)?;
        if !(0.0..=1.0).contains(&rf.text_dropout) {
            return Err(bad(format!("rf.text_dropout {} is outside [0, 1]", rf.text_dropout)));
        }
        if !(0.0..=1.0).contains(&rf.tau_star) {
            return Err(bad(format!("rf.tau_star {} is outside [0, 1]", rf.tau_star)));
        }
        if !(rf.keyframe_noise >= 0.0 && rf.keyframe_noise.is_finite()) {
            return Err(bad(format!(
                "rf.keyframe_noise {} must be finite and non-negative",
                rf.keyframe_noise
            )));
        }
        if rf.k_max > cfg.model.frames {
            return Err(bad(format!(
                "rf.k_max {} exceeds model.frames {}",
                rf.k_max, cfg.model.frames
            )));
        }
        if rf.kf_sampler == TrainingKeyframes::Scenemi && cfg.model.frames < 2 {
            return Err(bad(format!(
                "rf.kf_sampler = \"scenemi\" keeps the first and last frames: needs model.frames ≥ 2, got {}",
                cfg.model.frames
            )));
        }
        if rf.kf_sampler == TrainingKeyframes::FirstLast {
            rf.kf_sampler.strategy(rf.k_max).check(cfg.model.frames).map_err(|e| {
                bad(format!(
                    "rf.kf_sampler = \"first_last\" with rf.k_max = {}: {e}",
                    rf.k_max
                ))
            })?;
        }
        if let Anchor::KeyframeLerp { .. } = cfg.model.anchor
            && !matches!(rf.kf_sampler, TrainingKeyframes::FirstLast | TrainingKeyframes::Scenemi)
        {
            return Err(bad(format!(
                "model.anchor = keyframe_lerp needs training keyframes that always include the first and last frames \
                 (rf.kf_sampler = \"first_last\" or \"scenemi\"), got {:?}: without them the anchor extrapolates",
                rf.kf_sampler
            )));
        }
        if rf.valid_sample_every > 0 {
            if !rf.valid_sample_every.is_multiple_of(cfg.train.valid_every) {
                return Err(bad(format!(
                    "rf.valid_sample_every {} must be a multiple of train.valid_every {} (samples are drawn at \
                     validations), or 0 for off",
                    rf.valid_sample_every, cfg.train.valid_every
                )));
            }
            if rf.valid_sample_clips == 0 {
                return Err(bad("rf.valid_sample_clips must be positive when sampling is on".into()));
            }
            if rf.valid_sample_grid < 2 {
                return Err(bad(format!(
                    "rf.valid_sample_grid {} must be at least 2",
                    rf.valid_sample_grid
                )));
            }
            // The AnimateAnyMesh reference (one trajectory slot, no keyframes) samples whole store windows: their
            // length is checked against the store when the run starts.
            let aam = cfg.model.frames == 1 && cfg.model.conditioning == KeyframeConditioning::None;
            if !aam {
                VALID_SAMPLE_KEYFRAMES
                    .check(cfg.model.frames)
                    .map_err(|e| bad(format!("rf.valid_sample_every > 0 needs model.frames ≥ 3: {e}")))?;
            }
        }
        if rf.latent_cache == LatentCache::Disk && cfg.model.scene.any() {
            return Err(bad(
                "rf.latent_cache = \"disk\" keeps no scene features: use \"memory\" or \"per_batch\" with model.scene"
                    .into(),
            ));
        }
        rf.augment.validate("rf.augment").map_err(bad)?;
        if !rf.augment.is_off() {
            if rf.latent_cache != LatentCache::PerBatch {
                return Err(bad(
                    "rf.augment needs rf.latent_cache = \"per_batch\": latents cached at the start are of the stored, \
                     unaugmented clips"
                        .into(),
                ));
            }
            if cfg.model.conditioning == KeyframeConditioning::ImputeUntil {
                return Err(bad(
                    "rf.augment cannot be combined with model.conditioning = \"impute_until\" (its noisy keyframes \
                     are re-read from the store, unaugmented)"
                        .into(),
                ));
            }
        }
        let t = &cfg.text;
        for (name, value) in [
            ("vocab_size", t.vocab_size),
            ("layers", t.layers),
            ("heads", t.heads),
            ("max_len", t.max_len),
        ] {
            if value == 0 {
                return Err(bad(format!("text.{name} must be positive, got 0")));
            }
        }
        if !cfg.model.text_dim.is_multiple_of(t.heads) {
            return Err(bad(format!(
                "text.heads ({}) must divide model.text_dim ({})",
                t.heads, cfg.model.text_dim
            )));
        }
        Ok(cfg)
    }

    crate::config::loading_methods!();

    /// The fully resolved config as TOML.
    pub fn to_toml(&self) -> Result<String> {
        to_toml(self)
    }

    /// The network of this config for a trained tokenizer of `vocab_size` tokens.
    pub fn model_config(&self, vocab_size: usize) -> RfModelConfig {
        RfModelConfig {
            mmdit: self.model.clone(),
            text: ScratchTextConfig {
                vocab_size,
                width: self.model.text_dim,
                layers: self.text.layers,
                heads: self.text.heads,
                max_len: self.text.max_len,
            },
        }
    }

    /// The options of (R5) for this config.
    pub fn loss_options(&self) -> RfLossOptions {
        RfLossOptions {
            conditioning: self.model.conditioning,
            keyframe_loss: self.rf.keyframe_loss,
            tau_star: self.rf.tau_star,
        }
    }
}
