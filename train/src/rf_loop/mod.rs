//! Rectified-flow training (docs/method.md §4.2, §4.4–4.7, §5.4): `any4d train rf`. The frozen VAE of
//! `--vae RUN` encodes the clips (posterior μ, log σ², z₀) — once at run start into host memory, or per
//! micro-batch (`rf.latent_cache`); each step draws z = μ + σξ (or μ), standardizes it (docs/method.md §3.4), draws
//! keyframe masks (§4.5, §5.4; SceneMI's noisy keyframes for `impute_until` are noised in vertex space and encoded per
//! batch), τ, ε and the CFG text dropout, and minimises (R5) through `rf_training_loss`. The caption encoder is the
//! `scratch` one: its tokenizer is trained on the TRAIN captions at run start (`tokenizer.json` in the run folder)
//! and its transformer is trained jointly with the MMDiT ([`RfModel`]). Run config: `configs/rf/*.toml`
//! (`[model]`, `[rf]`, `[text]`, `[train]`, `[optim]`, `[device]`).
//!
//! Files: `config.rs` (the TOML), `network.rs` (MMDiT + caption encoder), `latents.rs` (frozen-VAE latents),
//! `batcher.rs` ([`RfBatcher`]: the batches), `objective.rs` ([`RfObjective`]: (R5) and validation),
//! `validation.rs` (validation samples: a few VAL clips completed by the current network through the eval crate's
//! sampler, docs/method.md §4.6, and scored with (E1)–(E3), `samples.csv`), `run.rs` (`train rf`, `--resume`).

use any4d_data::keyframes::KeyframeStrategy;

mod batcher;
mod config;
mod latent_files;
mod latents;
mod network;
mod objective;
mod run;
mod validation;

pub use batcher::*;
pub use config::*;
pub use latent_files::{
    DiskLatents, Encoder, FileState, LatentHeader, check_file, encode_store_latents, shard_file, vae_fingerprint,
};
pub use latents::*;
pub use network::*;
pub use objective::*;
pub use run::*;
pub use validation::*;

/// Names of the loss terms in `metrics.csv` / `valid.csv`: (R5) and the fraction of keyframe slots (m = 1).
pub const RF_TERMS: [&str; 2] = ["rf", KF_FRAC_TERM];

/// The RF's diagnostic `metrics.csv` column: the fraction of latent frames that are keyframes (not a loss).
pub const KF_FRAC_TERM: &str = "kf_frac";

/// Columns of `samples.csv` after `step`: (E1) RMSE, (E2) Chamfer, (E3) centroid DTW of docs/method.md §6, means over
/// the sampled VAL clips.
pub const SAMPLE_TERMS: [&str; 3] = ["rmse", "chamfer", "dtw"];

/// Keyframes of the validation samples: frames 0 and T − 1 and one interior frame (docs/method.md §6.1's protocol with
/// K_x = 1), drawn once per clip from a fixed seed.
pub const VALID_SAMPLE_KEYFRAMES: KeyframeStrategy = KeyframeStrategy::FirstLastPlus(1);
