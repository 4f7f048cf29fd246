//! Run configs : plain serde structs with `deny_unknown_fields` for the tables this
//! crate owns (`[train]`, `[optim]`, `[device]`, …), and a strict key check of the model's burn `Config` under
//! `[model]` (burn's derive accepts unknown keys silently). Every hyper-parameter comes from TOML; docs/method.md §3.5
//! (VAE) and §4.7 (RF) give the paper values in `configs/{vae,rf}/paper.toml`.

use std::path::Path;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::backend::{Backend, Precision};
use crate::error::{Result, TrainError};

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
}

/// The `[optim]` table: AdamW with global-norm gradient clipping and a constant learning rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimConfig {
    /// Constant learning rate (docs/method.md §3.5: 1e-4 VAE; §4.7: 2e-4 RF).
    pub lr: f64,
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
        if self.progress_every_secs.is_nan() || self.progress_every_secs <= 0.0 {
            return bad("progress_every_secs", "must be positive".into());
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
            && self.grad_clip > 0.0;
        if ok {
            Ok(())
        } else {
            Err(TrainError::Config {
                path: file.to_path_buf(),
                reason: format!("optim: out of range (need lr>0, 0≤β<1, wd≥0, eps>0, grad_clip>0): {self:?}"),
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

/// Parses TOML text into the strict run-config type `C`; `file` names the source in errors.
pub fn parse_strict<C: DeserializeOwned>(text: &str, file: &Path) -> Result<C> {
    toml::from_str(text).map_err(|e| TrainError::Config {
        path: file.to_path_buf(),
        reason: e.to_string(),
    })
}

/// Reads a TOML file into `C`.
pub fn load_strict<C: DeserializeOwned>(file: &Path) -> Result<C> {
    let text = std::fs::read_to_string(file).map_err(crate::error::io_err("read config", file))?;
    parse_strict(&text, file)
}

/// Serialises a resolved config to TOML (the run folder's `config.toml`).
pub fn to_toml<C: Serialize>(config: &C) -> Result<String> {
    toml::to_string(config).map_err(|e| TrainError::Config {
        path: "<resolved>".into(),
        reason: e.to_string(),
    })
}

/// Deserialises a model `Config` (lenient in burn) from `table` and rejects any key it does not know or any
/// key it needs that is absent: the parsed config is serialised again and the two key trees must agree.
/// `section` names the table in errors (e.g. `model`).
pub fn strict_model_config<M>(table: &toml::Value, section: &str, file: &Path) -> Result<M>
where
    M: DeserializeOwned + Serialize,
{
    let err = |reason: String| TrainError::Config {
        path: file.to_path_buf(),
        reason,
    };
    let parsed: M = table.clone().try_into().map_err(|e| err(format!("[{section}]: {e}")))?;
    let back = toml::Value::try_from(&parsed).map_err(|e| err(format!("[{section}]: {e}")))?;
    compare_keys(table, &back, section).map_err(err)?;
    Ok(parsed)
}

fn compare_keys(given: &toml::Value, known: &toml::Value, path: &str) -> std::result::Result<(), String> {
    let (toml::Value::Table(given), toml::Value::Table(known)) = (given, known) else {
        return Ok(());
    };
    if let Some(k) = given.keys().find(|k| !known.contains_key(*k)) {
        return Err(format!("unknown key `{path}.{k}`"));
    }
    if let Some(k) = known.keys().find(|k| !given.contains_key(*k)) {
        return Err(format!("missing key `{path}.{k}`"));
    }
    for (k, v) in given {
        compare_keys(v, &known[k], &format!("{path}.{k}"))?;
    }
    Ok(())
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
beta1 = 0.9
beta2 = 0.999
weight_decay = 1e-4
eps = 1e-8
grad_clip = 1.0

[device]
backend = "flex"
precision = "f32"
"#;

    #[test]
    fn round_trip_and_unknown_keys_are_rejected() {
        let p = Path::new("t.toml");
        let run: Run = parse_strict(TEXT, p).unwrap();
        assert_eq!(run.train.duration, Duration::Steps(10));
        assert_eq!(run.train.accumulation(), 2);
        let back: Run = parse_strict(&to_toml(&run).unwrap(), p).unwrap();
        assert_eq!(back, run);

        let typo = TEXT.replace("keep_last", "keep_lats");
        let err = parse_strict::<Run>(&typo, p).unwrap_err().to_string();
        assert!(err.contains("keep_lats") && err.contains("t.toml"), "{err}");
        let missing = TEXT.replace("eps = 1e-8\n", "");
        assert!(
            parse_strict::<Run>(&missing, p)
                .unwrap_err()
                .to_string()
                .contains("eps")
        );
        let bad_backend = TEXT.replace("\"flex\"", "\"tpu\"");
        assert!(parse_strict::<Run>(&bad_backend, p).is_err());
    }

    #[test]
    fn model_tables_are_checked_key_by_key() {
        #[derive(Debug, Serialize, Deserialize)]
        struct Inner {
            width: usize,
        }
        #[derive(Debug, Serialize, Deserialize)]
        struct Lenient {
            d: usize,
            inner: Inner,
        }
        let ok: toml::Value = toml::from_str("d = 4\n[inner]\nwidth = 2\n").unwrap();
        let m: Lenient = strict_model_config(&ok, "model", Path::new("m.toml")).unwrap();
        assert_eq!((m.d, m.inner.width), (4, 2));
        let extra: toml::Value = toml::from_str("d = 4\n[inner]\nwidth = 2\nheads = 3\n").unwrap();
        let err = strict_model_config::<Lenient>(&extra, "model", Path::new("m.toml")).unwrap_err();
        assert!(err.to_string().contains("unknown key `model.inner.heads`"), "{err}");
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
    }
}
