//! `any4d train bdlstm`: a new or resumed BD-LSTM run of either variant, told apart by `model.variant`: the latent
//! adaptation on a frozen VAE ([`crate::bdlstm_loop`], docs/method.md §5.3) or the original on ACAP features of a
//! single-topology store ([`crate::bdlstm_acap`]). Both train on one device.

use std::path::Path;

use crate::backend;
use crate::bdlstm_loop::{BdlstmRunConfig, BdlstmRunOptions, BdlstmVariant};
use crate::error::{Result, TrainError};
use crate::loop_common::Outcome;
use crate::run_folder::{RunFolder, open_for_resume};

/// Starts a new BD-LSTM run with `cfg`: on the frozen VAE of `opts.vae_run` (latent variant) or on the ACAP features
/// of the store (`model.variant = "acap"`, no VAE).
pub fn train_bdlstm(cfg: &BdlstmRunConfig, opts: &BdlstmRunOptions) -> Result<(RunFolder, Outcome)> {
    if opts.run.parallel.is_some() {
        return Err(TrainError::Setup(
            "BD-LSTM runs train on one device (no --devices)".into(),
        ));
    }
    match cfg.model.variant {
        BdlstmVariant::Acap => crate::bdlstm_acap::train_acap(cfg, opts),
        BdlstmVariant::Latent => crate::bdlstm_loop::train_latent(cfg, opts),
    }
}

/// Continues the BD-LSTM run in `run_dir` from its newest checkpoint.
pub fn resume_bdlstm(run_dir: &Path, backend: Option<backend::Backend>, opts: &BdlstmRunOptions) -> Result<Outcome> {
    let (run, cfg, ckpt) = open_for_resume(run_dir, BdlstmRunConfig::parse, backend, |c: &mut BdlstmRunConfig| {
        &mut c.device
    })?;
    match cfg.model.variant {
        BdlstmVariant::Acap => crate::bdlstm_acap::resume_acap(&cfg, &run, ckpt, opts),
        BdlstmVariant::Latent => crate::bdlstm_loop::resume_latent(&cfg, &run, ckpt, opts),
    }
}
