//! Reducing a trained run folder to what sampling needs (`any4d model pack`): the resolved config, the newest
//! checkpoint's sampling parameters (the average of docs/method.md §4.8 when the run keeps one) as `model.bpk`,
//! its `state.json`, and the run's side files (latent statistics of a VAE; tokenizer and VAE record of an RF; VAE
//! record of a BD-LSTM; for an RF started with `--init`, its `init.json`, which names the checkpoint its parameters
//! started from). No optimiser state: a packed folder loads everywhere a run folder does (`--vae`, `--rf`,
//! `--baseline-rf`, `--aam`, `--bdlstm`) but
//! cannot resume. Parameters may be stored in half precision; loading casts them back to the model's precision
//! (`checkpoint::load_model`).

use std::fs;
use std::path::{Path, PathBuf};

use any4d_model::any_vae::AnyMeshVae;
use any4d_model::text::scratch::TOKENIZER_FILE;
use burn::module::{Module, ModuleMapper, Param};
use burn::prelude::{Device, Tensor};
use burn::tensor::DType;

use crate::bdlstm_acap::{ACAP_FILE, load_acap_bdlstm_run};
use crate::bdlstm_loop::{BdlstmVariant, load_bdlstm_run, read_bdlstm_config};
use crate::checkpoint::{MODEL_FILE, STATE_FILE, step_dir_name};
use crate::error::{Result, TrainError, io_err, run_err};
use crate::rf_loop::INIT_FILE;
use crate::run_folder::{CHECKPOINTS_DIR, CONFIG_FILE};
use crate::runs::{VAE_RUN_FILE, VaeRunRecord, load_rf_run, load_vae_run, newest_checkpoint, read_vae_record};
use crate::vae_loop::LATENT_STATS_FILE;

/// Storage precision of packed parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// As trained (f32).
    Full,
    /// IEEE half precision: half the size; loading casts back to f32.
    Half,
}

/// What [`pack_run`] wrote.
#[derive(Debug)]
pub struct Packed {
    /// "VAE", "RF" or "BD-LSTM".
    pub kind: &'static str,
    /// The checkpoint step packed.
    pub step: u64,
    /// Whether the parameters are the run's average (docs/method.md §4.8) rather than its trained ones.
    pub averaged: bool,
    /// Bytes of the written `model.bpk`.
    pub model_bytes: u64,
}

/// Casts every float parameter of a module to one dtype.
struct CastParams(DType);

impl ModuleMapper for CastParams {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let dtype = self.0;
        param.map(|t| t.cast(dtype))
    }
}

/// Saves `model`'s parameters to `path` in `precision`.
pub fn save_params<M: Module>(model: M, path: &Path, precision: Precision) -> Result<()> {
    let model = match precision {
        Precision::Full => model,
        Precision::Half => model.map(&mut CastParams(DType::F16)),
    };
    model.save_file(path).map_err(|e| TrainError::Checkpoint {
        path: path.to_path_buf(),
        reason: format!("save parameters: {e}"),
    })
}

/// Packs the run folder `run` (a VAE, RF or BD-LSTM run of either variant) into the new folder `out`. `vae_at`, for an RF run, replaces the
/// recorded VAE folder in `vae_run.json` (e.g. `../vae` when the VAE is packed beside it); the step stays the
/// recorded one. `out` must not exist; it is written under a temporary name and renamed into place, so an
/// interrupted pack leaves no half folder.
pub fn pack_run(
    run: &Path,
    out: &Path,
    precision: Precision,
    vae_at: Option<&Path>,
    device: &Device,
) -> Result<Packed> {
    if out.exists() {
        return Err(run_err(out, "exists; pack writes a new folder (remove it first)"));
    }
    // RF and BD-LSTM runs record the VAE they were trained on; a BD-LSTM config has a [bdlstm] table.
    let on_vae = run.join(VAE_RUN_FILE).is_file();
    // An ACAP BD-LSTM run records its reference mesh and feature scaling instead of a VAE.
    let is_acap = !on_vae && read_bdlstm_config(run).is_ok_and(|(_, c)| c.model.variant == BdlstmVariant::Acap);
    if !on_vae && vae_at.is_some() {
        return Err(run_err(
            run,
            "a VAE or ACAP BD-LSTM run (no `vae_run.json`); `--vae-at` applies to RF and latent BD-LSTM runs only",
        ));
    }
    let is_bdlstm = on_vae && {
        let config = run.join(CONFIG_FILE);
        let text = fs::read_to_string(&config).map_err(io_err("read", &config))?;
        text.parse::<toml::Table>().is_ok_and(|t| t.contains_key("bdlstm"))
    };
    let tmp = temp_sibling(out, "pack")?;
    let packed = if is_acap {
        let bd = load_acap_bdlstm_run(run, device)?;
        let (ckpt, _) = newest_checkpoint(&bd.run)?;
        let ckpt_out = write_common(&bd.run, &ckpt, bd.step, &tmp)?;
        copy(&bd.run, &tmp, ACAP_FILE)?;
        let averaged = ckpt.join(crate::checkpoint::EMA_FILE).is_file();
        save_params(bd.model, &ckpt_out.join(MODEL_FILE), precision)?;
        finish("BD-LSTM (ACAP)", bd.step, averaged, &ckpt_out)?
    } else if is_bdlstm {
        let bd = load_bdlstm_run(run, device)?;
        let (ckpt, _) = newest_checkpoint(&bd.run)?;
        let ckpt_out = write_common(&bd.run, &ckpt, bd.step, &tmp)?;
        write_vae_record(&bd.run, &tmp, vae_at)?;
        let averaged = ckpt.join(crate::checkpoint::EMA_FILE).is_file();
        save_params(bd.model, &ckpt_out.join(MODEL_FILE), precision)?;
        finish("BD-LSTM", bd.step, averaged, &ckpt_out)?
    } else if on_vae {
        let rf = load_rf_run(run, device)?;
        let ckpt_out = write_common(&rf.run, &rf.checkpoint, rf.step, &tmp)?;
        copy(&rf.run, &tmp, TOKENIZER_FILE)?;
        write_vae_record(&rf.run, &tmp, vae_at)?;
        if rf.run.join(INIT_FILE).is_file() {
            copy(&rf.run, &tmp, INIT_FILE)?;
        }
        let averaged = rf.checkpoint.join(crate::checkpoint::EMA_FILE).is_file();
        save_params(rf.model, &ckpt_out.join(MODEL_FILE), precision)?;
        finish("RF", rf.step, averaged, &ckpt_out)?
    } else {
        let vae = load_vae_run(run, device)?;
        let ckpt_out = write_common(&vae.run, &vae.checkpoint, vae.step, &tmp)?;
        copy(&vae.run, &tmp, LATENT_STATS_FILE)?;
        let averaged = vae.checkpoint.join(crate::checkpoint::EMA_FILE).is_file();
        let path = ckpt_out.join(MODEL_FILE);
        match vae.model {
            AnyMeshVae::Framewise(m) => save_params(m, &path, precision)?,
            AnyMeshVae::Sequencewise(m) => save_params(m, &path, precision)?,
        }
        finish("VAE", vae.step, averaged, &ckpt_out)?
    };
    fs::rename(&tmp, out).map_err(io_err("rename packed folder into place", out))?;
    Ok(packed)
}

/// Copies the run's `vae_run.json` into `tmp`, its folder replaced by `vae_at` when given (the step stays).
fn write_vae_record(run: &Path, tmp: &Path, vae_at: Option<&Path>) -> Result<()> {
    let mut record = read_vae_record(run)?;
    if let Some(at) = vae_at {
        record = VaeRunRecord {
            run: at.to_path_buf(),
            step: record.step,
        };
    }
    let json =
        serde_json::to_vec_pretty(&record).map_err(|e| run_err(tmp, format!("serialise {VAE_RUN_FILE}: {e}")))?;
    fs::write(tmp.join(VAE_RUN_FILE), json).map_err(io_err("write", tmp.join(VAE_RUN_FILE)))
}

/// Creates `tmp/checkpoints/step_N/` with the checkpoint's `state.json`, and copies the run's config.
fn write_common(run: &Path, ckpt: &Path, step: u64, tmp: &Path) -> Result<PathBuf> {
    let ckpt_out = tmp.join(CHECKPOINTS_DIR).join(step_dir_name(step));
    fs::create_dir_all(&ckpt_out).map_err(io_err("create", &ckpt_out))?;
    copy(run, tmp, CONFIG_FILE)?;
    copy(ckpt, &ckpt_out, STATE_FILE)?;
    Ok(ckpt_out)
}

fn copy(from_dir: &Path, to_dir: &Path, file: &str) -> Result<()> {
    let from = from_dir.join(file);
    fs::copy(&from, to_dir.join(file)).map_err(io_err("copy", &from))?;
    Ok(())
}

fn finish(kind: &'static str, step: u64, averaged: bool, ckpt_out: &Path) -> Result<Packed> {
    let p = ckpt_out.join(MODEL_FILE);
    let model_bytes = fs::metadata(&p).map_err(io_err("stat", &p))?.len();
    Ok(Packed {
        kind,
        step,
        averaged,
        model_bytes,
    })
}

/// The temporary sibling `.tmp_<what>_<name>` that the folder `out` is written as before it is renamed into place;
/// a stale one (left by a killed run of the same command: ours, incomplete) is removed.
pub(crate) fn temp_sibling(out: &Path, what: &str) -> Result<PathBuf> {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = out.with_file_name(format!(".tmp_{what}_{name}"));
    if tmp.exists() {
        fs::remove_dir_all(&tmp).map_err(io_err("remove stale temporary folder", &tmp))?;
    }
    Ok(tmp)
}
