//! Run configs: plain serde structs with `deny_unknown_fields` for every table, the model's included (one idiom
//! across the crates), read through [`resolve`] (`extends` chains and `--set` overrides). Every hyper-parameter
//! comes from TOML; docs/method.md §3.5 (VAE) and §4.7 (RF) give the paper values in `configs/{vae,rf}/paper.toml`.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::backend::{Backend, Precision};
use crate::error::{Result, TrainError};

pub mod resolve;

pub use resolve::{ConfigSource, Embedded, Files, Override};

/// `parse`, `load_with` and `load` of a run config, around its own `from_table(table, file)`: both run kinds read
/// their files the same way (`extends`, then `--set`, then the strict table check).
macro_rules! loading_methods {
    () => {
        /// Parses the text of `file` (its `extends` chain read from the file system).
        pub fn parse(text: &str, file: &std::path::Path) -> $crate::error::Result<Self> {
            let files = $crate::config::Files;
            Self::from_table($crate::config::resolve::resolve_text(&files, text, file)?, file)
        }

        /// Reads `file` from `source` with its `extends` chain and `overrides`.
        pub fn load_with(
            source: &dyn $crate::config::ConfigSource,
            file: &std::path::Path,
            overrides: &[$crate::config::Override],
        ) -> $crate::error::Result<Self> {
            Self::from_table($crate::config::resolve::resolve(source, file, overrides)?, file)
        }

        /// Reads a config file with `overrides` (`--set`).
        pub fn load(file: &std::path::Path, overrides: &[$crate::config::Override]) -> $crate::error::Result<Self> {
            Self::load_with(&$crate::config::Files, file, overrides)
        }
    };
}
pub(crate) use loading_methods;

/// How long a run trains.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Duration {
    /// Passes over the training set (docs/method.md §3.5: 200 VAE, §4.7: 1000 RF); rounded up to whole steps.
    Epochs(u64),
    /// A fixed number of optimiser steps (tests, benchmarks).
    Steps(u64),
}

impl Duration {
    /// Optimiser steps for a training set of `len` examples at global batch `batch`.
    pub fn steps(self, len: usize, batch: usize) -> u64 {
        match self {
            Duration::Steps(s) => s,
            Duration::Epochs(e) => (e * len as u64).div_ceil(batch as u64),
        }
    }
}

/// The `[train]` table: loop, batch and bookkeeping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Seed of initialisation, data order and every random draw (docs/method.md §3.5, §4.7: 666).
    pub seed: u64,
    /// Training length.
    pub duration: Duration,
    /// Global batch: examples per optimiser step (docs/method.md §1.1: 256).
    pub batch_size: usize,
    /// Examples per forward/backward pass; `batch_size` must be a multiple (gradient accumulation).
    pub micro_batch: usize,
    /// Write a checkpoint every this many steps (and at the end, on Ctrl-C and on a new best validation).
    pub checkpoint_every: u64,
    /// Checkpoints kept besides the best validation one.
    pub keep_last: usize,
    /// Validate every this many steps.
    pub valid_every: u64,
    /// Seconds between compact progress lines when stdout is not a terminal.
    pub progress_every_secs: f64,
    /// Decay d of an exponential moving average of the parameters (docs/method.md §4.8), used for validation and
    /// sampling and saved next to the raw parameters; 0 = off (the paper). Absent from a file means 0.
    #[serde(default)]
    pub ema_decay: f64,
    /// Flush subnormal floats to zero on the threads that train (docs/method.md §10): CPU steps keep their speed as
    /// the network learns. Every preset sets it; absent from a file means false, so a run made before the key
    /// existed resumes as it trained.
    #[serde(default)]
    pub flush_denormals: bool,
    /// On a sharded store, examples held by the shuffle buffer that mixes the shards an epoch reads one after
    /// another (docs/training.md, "Data order on a sharded store"); a one-file store is shuffled whole and ignores
    /// it. Absent from a file means 0: each shard's examples in their own shuffled order.
    #[serde(default)]
    pub shuffle_buffer: usize,
}

/// How the learning rate moves over a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum LrSchedule {
    /// `lr` at every step (the paper's VAE and RF).
    Constant,
    /// Linear warm-up from 0 to `lr` over `warmup_steps`, then a half cosine from `lr` down to
    /// `final_fraction · lr` at the last step of the run.
    WarmupCosine {
        /// Steps of the linear warm-up.
        warmup_steps: u64,
        /// Learning rate at the last step as a fraction of `lr`, in [0, 1].
        final_fraction: f64,
    },
}

impl LrSchedule {
    /// Learning rate of optimiser step `step` (1-based) of a `total`-step run with peak `lr`.
    pub fn lr(self, lr: f64, step: u64, total: u64) -> f64 {
        match self {
            LrSchedule::Constant => lr,
            LrSchedule::WarmupCosine {
                warmup_steps,
                final_fraction,
            } => {
                if step <= warmup_steps {
                    return lr * step as f64 / warmup_steps.max(1) as f64;
                }
                let span = total.saturating_sub(warmup_steps).max(1) as f64;
                let progress = ((step - warmup_steps) as f64 / span).min(1.0);
                let cosine = 0.5 * (1.0 + (std::f64::consts::PI * progress).cos());
                lr * (final_fraction + (1.0 - final_fraction) * cosine)
            }
        }
    }
}

/// The `[optim]` table: AdamW with global-norm gradient clipping and a learning-rate schedule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimConfig {
    /// Peak learning rate (docs/method.md §3.5: 1e-4 VAE; §4.7: 2e-4 RF, both constant).
    pub lr: f64,
    /// Schedule of the learning rate around `lr` (paper: constant).
    pub schedule: LrSchedule,
    /// AdamW β₁ (0.9 both).
    pub beta1: f32,
    /// AdamW β₂ (0.999 VAE, 0.99 RF).
    pub beta2: f32,
    /// Decoupled weight decay (1e-4 VAE, 0.01 RF).
    pub weight_decay: f32,
    /// AdamW ε (the papers do not state it; 1e-8 is PyTorch's default, which the AAM code uses).
    pub eps: f32,
    /// Maximum global gradient L2 norm (1.0 both).
    pub grad_clip: f64,
}

/// The `[device]` table; `--backend` on the command line overrides `backend`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    /// Compute backend.
    pub backend: Backend,
    /// Float precision (the paper: FP32).
    pub precision: Precision,
}

impl TrainConfig {
    /// Checks value ranges; `file` names the config in the error.
    pub fn validate(&self, file: &Path) -> Result<()> {
        let bad = |field: &str, reason: String| {
            Err(TrainError::Config {
                path: file.to_path_buf(),
                reason: format!("train.{field}: {reason}"),
            })
        };
        if self.batch_size == 0 || self.micro_batch == 0 {
            return bad("batch_size", "batch_size and micro_batch must be positive".into());
        }
        // A bound no real run reaches, checked before a batch is allocated from it.
        const MAX_BATCH: usize = 1 << 20;
        if self.batch_size > MAX_BATCH || self.micro_batch > MAX_BATCH {
            return bad(
                "batch_size",
                format!(
                    "batch_size {} / micro_batch {} exceed {MAX_BATCH} clips",
                    self.batch_size, self.micro_batch
                ),
            );
        }
        if !self.batch_size.is_multiple_of(self.micro_batch) {
            return bad(
                "micro_batch",
                format!(
                    "batch_size {} is not a multiple of micro_batch {}",
                    self.batch_size, self.micro_batch
                ),
            );
        }
        if self.checkpoint_every == 0 || self.valid_every == 0 {
            return bad(
                "checkpoint_every",
                "checkpoint_every and valid_every must be positive".into(),
            );
        }
        if self.keep_last == 0 {
            return bad("keep_last", "must keep at least one checkpoint".into());
        }
        if !(0.0..1.0).contains(&self.ema_decay) {
            return bad("ema_decay", format!("{} is outside [0, 1)", self.ema_decay));
        }
        // Also refuses inf, which a Duration cannot hold.
        if !self.progress_every_secs.is_finite() || self.progress_every_secs <= 0.0 {
            return bad(
                "progress_every_secs",
                format!(
                    "must be a positive finite number of seconds, got {}",
                    self.progress_every_secs
                ),
            );
        }
        Ok(())
    }

    /// Micro-batches per optimiser step.
    pub fn accumulation(&self) -> usize {
        self.batch_size / self.micro_batch
    }
}

impl OptimConfig {
    /// Checks value ranges; `file` names the config in the error.
    pub fn validate(&self, file: &Path) -> Result<()> {
        let ok = self.lr > 0.0
            && (0.0..1.0).contains(&self.beta1)
            && (0.0..1.0).contains(&self.beta2)
            && self.weight_decay >= 0.0
            && self.eps > 0.0
            && self.grad_clip > 0.0
            && match self.schedule {
                LrSchedule::Constant => true,
                LrSchedule::WarmupCosine { final_fraction, .. } => (0.0..=1.0).contains(&final_fraction),
            };
        if ok {
            Ok(())
        } else {
            Err(TrainError::Config {
                path: file.to_path_buf(),
                reason: format!(
                    "optim: out of range (need lr>0, 0≤β<1, wd≥0, eps>0, grad_clip>0, final_fraction in [0, 1]): {self:?}"
                ),
            })
        }
    }

    /// The AdamW optimiser (clipping is done by the loop on the global norm, not per tensor as burn's is).
    pub fn init(&self) -> burn::optim::ModuleOptimizer {
        burn::optim::AdamWConfig::new()
            .with_beta_1(self.beta1)
            .with_beta_2(self.beta2)
            .with_weight_decay(self.weight_decay)
            .with_epsilon(self.eps)
            .init()
    }
}

/// Serialises a resolved config to TOML (the run folder's `config.toml`).
pub fn to_toml<C: Serialize>(config: &C) -> Result<String> {
    toml::to_string(config).map_err(|e| TrainError::Config {
        path: "<resolved>".into(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Run {
        train: TrainConfig,
        optim: OptimConfig,
        device: DeviceConfig,
    }

    const TEXT: &str = r#"
[train]
seed = 666
duration = { steps = 10 }
batch_size = 8
micro_batch = 4
checkpoint_every = 5
keep_last = 3
valid_every = 5
progress_every_secs = 5.0

[optim]
lr = 1e-4
schedule = "constant"
beta1 = 0.9
beta2 = 0.999
weight_decay = 1e-4
eps = 1e-8
grad_clip = 1.0

[device]
backend = "flex"
precision = "f32"
"#;

    fn parse_strict(text: &str, p: &Path) -> Result<Run> {
        resolve::from_table(toml::from_str(text).unwrap(), p)
    }

    #[test]
    fn round_trip_and_unknown_keys_are_rejected() {
        let p = Path::new("t.toml");
        let run: Run = parse_strict(TEXT, p).unwrap();
        assert_eq!(run.train.duration, Duration::Steps(10));
        assert_eq!(run.train.accumulation(), 2);
        let back: Run = parse_strict(&to_toml(&run).unwrap(), p).unwrap();
        assert_eq!(back, run);

        let typo = TEXT.replace("keep_last", "keep_lats");
        let err = parse_strict(&typo, p).unwrap_err().to_string();
        assert!(err.contains("keep_lats") && err.contains("t.toml"), "{err}");
        let missing = TEXT.replace("eps = 1e-8\n", "");
        assert!(parse_strict(&missing, p).unwrap_err().to_string().contains("eps"));
        let bad_backend = TEXT.replace("\"flex\"", "\"tpu\"");
        assert!(parse_strict(&bad_backend, p).is_err());
    }

    #[test]
    fn invalid_values_name_the_field() {
        let p = Path::new("t.toml");
        let mut run: Run = parse_strict(TEXT, p).unwrap();
        run.train.micro_batch = 3;
        let err = run.train.validate(p).unwrap_err().to_string();
        assert!(err.contains("train.micro_batch"), "{err}");
        run.optim.grad_clip = 0.0;
        assert!(run.optim.validate(p).is_err());
        assert_eq!(Duration::Epochs(2).steps(10, 4), 5);
        run.optim.grad_clip = 1.0;
        run.optim.schedule = LrSchedule::WarmupCosine {
            warmup_steps: 2,
            final_fraction: 1.5,
        };
        assert!(
            run.optim
                .validate(p)
                .unwrap_err()
                .to_string()
                .contains("final_fraction")
        );
    }

    #[test]
    fn warmup_cosine_rises_linearly_then_falls_to_its_floor() {
        let s = LrSchedule::WarmupCosine {
            warmup_steps: 4,
            final_fraction: 0.1,
        };
        let lrs: Vec<f64> = (1..=14).map(|step| s.lr(2.0, step, 14)).collect();
        assert_eq!(&lrs[..4], &[0.5, 1.0, 1.5, 2.0]);
        assert!(lrs[4..].windows(2).all(|w| w[1] < w[0]), "{lrs:?}");
        assert!((lrs[13] - 0.2).abs() < 1e-12, "{lrs:?}");
        // Half way through the cosine: the mean of peak and floor.
        assert!((s.lr(2.0, 9, 14) - 1.1).abs() < 1e-12);
        assert_eq!(LrSchedule::Constant.lr(2.0, 7, 14), 2.0);
        let parsed: Run = parse_strict(
            &TEXT.replace(
                "schedule = \"constant\"",
                "schedule = { warmup_cosine = { warmup_steps = 4, final_fraction = 0.1 } }",
            ),
            Path::new("t.toml"),
        )
        .unwrap();
        assert_eq!(parsed.optim.schedule, s);
    }
}
