//! Checkpoints : `checkpoints/step_N/{model.bpk, optim.bpk, state.json}` with the
//! model, the optimiser state, the step, the host RNG and the data-order position, plus `ema.bpk` (the averaged
//! parameters, docs/method.md §4.8) when the run keeps an average. A checkpoint is written into
//! `checkpoints/.tmp_step_N/` and renamed into place, so a killed run leaves only complete checkpoints. Old
//! checkpoints are pruned to the last few plus the best validation: renamed to `.del_step_N/` first, then
//! deleted, so a run killed while deleting never leaves a `step_N/` that lacks its model.

use std::fs;
use std::path::{Path, PathBuf};

use any4d_data::io::write_atomic;
use burn::module::Module;
use burn::optim::ModuleOptimizer;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::data_order::DataOrder;
use crate::error::{Result, TrainError, io_err};

/// Model parameters (burnpack).
pub const MODEL_FILE: &str = "model.bpk";
/// Averaged parameters (burnpack, docs/method.md §4.8); only in runs with `train.ema_decay > 0`.
pub const EMA_FILE: &str = "ema.bpk";
/// Optimiser state (burnpack).
pub const OPTIM_FILE: &str = "optim.bpk";
/// [`TrainState`] as JSON; written last, so its presence marks a complete checkpoint.
pub const STATE_FILE: &str = "state.json";

/// Everything besides tensors that a resumed run needs to continue exactly.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrainState {
    /// Optimiser steps completed.
    pub step: u64,
    /// Host RNG (keyframes, τ, noise, text dropout) after `step` steps.
    pub rng: ChaCha8Rng,
    /// Data-order position after `step` steps.
    pub order: DataOrder,
    /// Best validation so far: (step, loss).
    pub best_valid: Option<(u64, f64)>,
}

/// Name of the folder of step `step`.
pub fn step_dir_name(step: u64) -> String {
    format!("step_{step}")
}

/// Writes a checkpoint of `step` under `dir` (the run's `checkpoints/`) and returns its folder. If a complete
/// checkpoint of this step already exists (a resumed run interrupted at once) it is kept and returned. `ema`, the
/// averaged parameters of a run that keeps them, goes to [`EMA_FILE`].
pub fn save<M: Module + Clone>(
    dir: &Path,
    model: &M,
    ema: Option<&M>,
    optim: &ModuleOptimizer,
    state: &TrainState,
) -> Result<PathBuf> {
    let final_dir = dir.join(step_dir_name(state.step));
    if final_dir.join(STATE_FILE).exists() {
        return Ok(final_dir);
    }
    let tmp = dir.join(format!(".tmp_{}", step_dir_name(state.step)));
    if tmp.exists() {
        // Left by a run killed while writing this same step: ours, incomplete, never a user's folder.
        fs::remove_dir_all(&tmp).map_err(io_err("remove stale temporary checkpoint", &tmp))?;
    }
    fs::create_dir_all(&tmp).map_err(io_err("create", &tmp))?;
    let ckpt_err = |what: &str, e: burn::store::RecordError| TrainError::Checkpoint {
        path: tmp.clone(),
        reason: format!("{what}: {e}"),
    };
    model
        .clone()
        .save_file(tmp.join(MODEL_FILE))
        .map_err(|e| ckpt_err("save model", e))?;
    if let Some(ema) = ema {
        ema.clone()
            .save_file(tmp.join(EMA_FILE))
            .map_err(|e| ckpt_err("save averaged model", e))?;
    }
    optim
        .save(tmp.join(OPTIM_FILE))
        .map_err(|e| ckpt_err("save optimiser", e))?;
    let json = serde_json::to_vec_pretty(state).map_err(|e| TrainError::Checkpoint {
        path: tmp.clone(),
        reason: format!("serialise state: {e}"),
    })?;
    write_atomic(&tmp.join(STATE_FILE), &json)?;
    let written = [MODEL_FILE, OPTIM_FILE].into_iter().chain(ema.map(|_| EMA_FILE));
    for f in written {
        let p = tmp.join(f);
        fs::File::open(&p)
            .and_then(|f| f.sync_all())
            .map_err(io_err("sync", &p))?;
    }
    if final_dir.exists() {
        // An incomplete step folder cannot come from this code (rename is atomic); refuse to touch it.
        return Err(TrainError::Checkpoint {
            path: final_dir,
            reason: "exists without state.json; not written by this program, left untouched".into(),
        });
    }
    fs::rename(&tmp, &final_dir).map_err(io_err("rename checkpoint into place", &final_dir))?;
    Ok(final_dir)
}

/// Complete checkpoints under `dir`, sorted by step.
pub fn list(dir: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let mut out = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_err("list", dir))? {
        let entry = entry.map_err(io_err("list", dir))?;
        let name = entry.file_name();
        let Some(step) = name
            .to_str()
            .and_then(|n| n.strip_prefix("step_"))
            .and_then(|s| s.parse::<u64>().ok())
        else {
            continue;
        };
        if entry.path().join(STATE_FILE).is_file() {
            out.push((step, entry.path()));
        }
    }
    out.sort_by_key(|(s, _)| *s);
    Ok(out)
}

/// The newest complete checkpoint under `dir`, if any.
pub fn latest(dir: &Path) -> Result<Option<PathBuf>> {
    Ok(list(dir)?.pop().map(|(_, p)| p))
}

/// Reads `state.json` of a checkpoint folder.
pub fn read_state(ckpt: &Path) -> Result<TrainState> {
    let p = ckpt.join(STATE_FILE);
    let text = fs::read_to_string(&p).map_err(io_err("read", &p))?;
    let state: TrainState = serde_json::from_str(&text).map_err(|e| TrainError::Checkpoint {
        path: p.clone(),
        reason: format!("bad state: {e}"),
    })?;
    Ok(TrainState {
        order: state.order.restored(),
        ..state
    })
}

/// Loads the trained parameters of a checkpoint (`model.bpk`) into `model` (built from the same config).
pub fn load_model<M: Module>(model: M, ckpt: &Path) -> Result<M> {
    load_file(model, &ckpt.join(MODEL_FILE))
}

/// Loads the averaged parameters of a checkpoint (`ema.bpk`, docs/method.md §4.8) into `model`; an error when
/// the checkpoint has none.
pub fn load_ema<M: Module>(model: M, ckpt: &Path) -> Result<M> {
    let p = ckpt.join(EMA_FILE);
    if !p.is_file() {
        return Err(TrainError::Checkpoint {
            path: p,
            reason: "missing: the run's config keeps averaged parameters (train.ema_decay > 0)".into(),
        });
    }
    load_file(model, &p)
}

/// The parameters a trained run samples with: the averaged ones when the checkpoint has them, else the trained
/// ones. Returns the model and whether it holds the average.
pub fn load_for_sampling<M: Module>(model: M, ckpt: &Path) -> Result<(M, bool)> {
    if ckpt.join(EMA_FILE).is_file() {
        Ok((load_ema(model, ckpt)?, true))
    } else {
        Ok((load_model(model, ckpt)?, false))
    }
}

/// Loads a parameter file into `model`, casting each tensor to the dtype of the parameter it fills: a file stored
/// in half precision (`any4d model pack --half`) loads into an f32 model as f32.
fn load_file<M: Module>(model: M, p: &Path) -> Result<M> {
    let err = |e: burn::store::RecordError| TrainError::Checkpoint {
        path: p.to_path_buf(),
        reason: e.to_string(),
    };
    let record = burn::store::ModuleRecord::load(p).map_err(err)?.cast_to_module_dtype();
    model.try_load_record(record).map_err(err)
}

/// Loads model, optimiser state and [`TrainState`] of a checkpoint.
pub fn load<M: Module>(ckpt: &Path, model: M, optim: ModuleOptimizer) -> Result<(M, ModuleOptimizer, TrainState)> {
    let state = read_state(ckpt)?;
    let model = load_model(model, ckpt)?;
    let p = ckpt.join(OPTIM_FILE);
    let optim = optim.load(&p).map_err(|e| TrainError::Checkpoint {
        path: p,
        reason: e.to_string(),
    })?;
    Ok((model, optim, state))
}

/// Deletes checkpoints under `dir` except the newest `keep_last` and the one at `best_step`, and what a run
/// killed during an earlier prune left behind (`.del_step_N/`).
pub fn prune(dir: &Path, keep_last: usize, best_step: Option<u64>) -> Result<()> {
    let all = list(dir)?;
    let cut = all.len().saturating_sub(keep_last);
    for (step, path) in &all[..cut] {
        if Some(*step) != best_step {
            let doomed = dir.join(format!("{DELETING_PREFIX}{}", step_dir_name(*step)));
            // Atomic: from here on the checkpoint is no longer listed, however far the deletion gets.
            fs::rename(path, &doomed).map_err(io_err("prune old checkpoint", path))?;
        }
    }
    for entry in fs::read_dir(dir).map_err(io_err("list", dir))? {
        let path = entry.map_err(io_err("list", dir))?.path();
        let ours = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(DELETING_PREFIX));
        if ours {
            fs::remove_dir_all(&path).map_err(io_err("delete pruned checkpoint", &path))?;
        }
    }
    Ok(())
}

/// Name prefix of a checkpoint folder being deleted by [`prune`].
const DELETING_PREFIX: &str = ".del_";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prune_keeps_last_and_best_and_clears_a_killed_prune() {
        let dir = tempfile::tempdir().unwrap();
        for step in 1..=4u64 {
            let d = dir.path().join(step_dir_name(step));
            fs::create_dir_all(&d).unwrap();
            fs::write(d.join(MODEL_FILE), b"m").unwrap();
            fs::write(d.join(STATE_FILE), b"{}").unwrap();
        }
        // What a run killed in the middle of deleting step 0 leaves: renamed, half deleted.
        let killed = dir.path().join(".del_step_0");
        fs::create_dir_all(&killed).unwrap();
        fs::write(killed.join(STATE_FILE), b"{}").unwrap();
        assert_eq!(
            list(dir.path()).unwrap().len(),
            4,
            "a folder being deleted is not a checkpoint"
        );
        prune(dir.path(), 2, Some(1)).unwrap();
        let steps: Vec<u64> = list(dir.path()).unwrap().into_iter().map(|(s, _)| s).collect();
        assert_eq!(steps, [1, 3, 4]);
        let mut left: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["step_1", "step_3", "step_4"]);
    }
}
