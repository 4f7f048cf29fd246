//! A run config of any kind (`any4d train`'s and `any4d bench train`'s `--config`), told apart by its tables: the
//! one place that knows every kind of run, above the loops that each parse their own.

use std::path::Path;

use crate::bdlstm_loop::BdlstmRunConfig;
use crate::config::{ConfigSource, Files, Override, resolve};
use crate::error::{Result, TrainError};
use crate::rf_loop::RfRunConfig;
use crate::vae_loop::VaeRunConfig;

/// A run config of any kind, told apart by its tables: `[vae]` → [`VaeRunConfig`], `[rf]` → [`RfRunConfig`],
/// `[bdlstm]` → [`BdlstmRunConfig`].
#[derive(Clone, Debug)]
pub enum RunConfig {
    /// A `configs/vae/*.toml` run.
    Vae(Box<VaeRunConfig>),
    /// A `configs/rf/*.toml` run.
    Rf(Box<RfRunConfig>),
    /// A `configs/bdlstm/*.toml` run.
    Bdlstm(Box<BdlstmRunConfig>),
}

impl RunConfig {
    /// Reads `path` from `source` with its `extends` chain and `overrides`, and parses it as the run config its
    /// tables announce; errors name the file, the dotted key and the reason.
    pub fn load_with(source: &dyn ConfigSource, path: &Path, overrides: &[Override]) -> Result<Self> {
        Self::from_table(resolve::resolve(source, path, overrides)?, path)
    }

    /// [`RunConfig::load_with`] from the file system.
    pub fn load(path: &Path, overrides: &[Override]) -> Result<Self> {
        Self::load_with(&Files, path, overrides)
    }

    /// Parses a resolved table.
    pub fn from_table(table: toml::Table, path: &Path) -> Result<Self> {
        if table.contains_key("bdlstm") {
            Ok(RunConfig::Bdlstm(Box::new(BdlstmRunConfig::from_table(table, path)?)))
        } else if table.contains_key("rf") {
            Ok(RunConfig::Rf(Box::new(RfRunConfig::from_table(table, path)?)))
        } else if table.contains_key("vae") {
            Ok(RunConfig::Vae(Box::new(VaeRunConfig::from_table(table, path)?)))
        } else {
            Err(TrainError::Config {
                path: path.to_path_buf(),
                reason: "neither an RF run config (no [rf] table, see configs/rf/), a VAE run config (no [vae] \
                         table, see configs/vae/) nor a BD-LSTM run config (no [bdlstm] table, see configs/bdlstm/)"
                    .into(),
            })
        }
    }
}
