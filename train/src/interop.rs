//! Run folders in and out of safetensors (`any4d model export` / `any4d model import`), for PyTorch and back
//! (docs/method.md §12; the names and checks are `any4d_model::interop`'s).
//!
//! An export folder holds `model.safetensors` (the network that has an AnimateAnyMesh counterpart: the MMDiT of an
//! RF run, or the VAE of a VAE run; the newest checkpoint's sampling parameters, the average when the run keeps
//! one), with the run's resolved config (as JSON), network, names and step in its header, and beside it what any4d needs to
//! use it again: `config.toml`, and for an RF `text_encoder.safetensors` (the scratch caption encoder, any4d's
//! names), `tokenizer.json` and `vae_run.json`, for a VAE `latent_stats.json`. Import reads such a folder's
//! `model.safetensors` (or a file written by PyTorch, with `--config`) back into a packed run folder that
//! `eval run`, `complete` and `train --init` load like any run.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use any4d_model::any_vae::{AnyMeshVae, AnyMeshVaeConfig};
use any4d_model::interop::{
    self, FileTensor, META_NAMES, META_NETWORK, Names, Network, aam_vae_buffers, collect_tensors,
};
use any4d_model::text::scratch::{ScratchTokenizer, TOKENIZER_FILE};
use burn::prelude::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::checkpoint::{MODEL_FILE, STATE_FILE, TrainState, step_dir_name};
use crate::data_order::DataOrder;
use crate::error::{Result, TrainError, io_err, run_err};
use crate::pack::{Precision, save_params, temp_sibling};
use crate::run_folder::{CHECKPOINTS_DIR, CONFIG_FILE};
use crate::runs::{VAE_RUN_FILE, load_rf_run};
use crate::vae_loop::{LATENT_STATS_FILE, VaeRunConfig};

/// The exported network's file.
pub const MODEL_SAFETENSORS: &str = "model.safetensors";
/// An RF export's caption encoder (any4d's names: it has no AnimateAnyMesh counterpart).
pub const TEXT_SAFETENSORS: &str = "text_encoder.safetensors";
/// Header metadata: the run's resolved `config.toml`.
pub const META_CONFIG: &str = "any4d.config";
/// Header metadata: the checkpoint step.
pub const META_STEP: &str = "any4d.step";

/// What [`export_run`] wrote.
#[derive(Debug)]
pub struct Exported {
    pub network: Network,
    pub step: u64,
    /// Tensors in `model.safetensors`.
    pub tensors: usize,
    /// Whether the parameters are the run's average rather than its trained ones.
    pub averaged: bool,
}

fn interop_err(e: interop::InteropError) -> TrainError {
    run_err(e.path.clone(), e.what())
}

/// The header metadata of an export: `config` (the run's resolved `config.toml`) as JSON, so that a reader
/// needs no TOML parser.
fn metadata(run: &Path, network: Network, names: Names, config: String, step: u64) -> Result<BTreeMap<String, String>> {
    let table: toml::Table = config
        .parse()
        .map_err(|e| run_err(run.join(CONFIG_FILE), format!("not TOML: {e}")))?;
    let config = serde_json::to_string(&table)
        .map_err(|e| run_err(run.join(CONFIG_FILE), format!("cannot be written as JSON: {e}")))?;
    Ok(BTreeMap::from([
        // What PyTorch's `safetensors.torch.save_file` writes: loaders that check it accept the file.
        ("format".to_owned(), "pt".to_owned()),
        (META_NETWORK.to_owned(), network.name().to_owned()),
        (META_NAMES.to_owned(), names.name().to_owned()),
        (META_CONFIG.to_owned(), config),
        (META_STEP.to_owned(), step.to_string()),
    ]))
}

/// Exports the run folder `run` (RF or VAE) into the new folder `out` (see the module doc).
pub fn export_run(run: &Path, out: &Path, names: Names, device: &Device) -> Result<Exported> {
    if out.exists() {
        return Err(run_err(out, "exists; export writes a new folder (remove it first)"));
    }
    let is_rf = run.join(VAE_RUN_FILE).is_file();
    let config_text = fs::read_to_string(run.join(CONFIG_FILE)).map_err(io_err("read", run.join(CONFIG_FILE)))?;
    if is_rf
        && config_text
            .parse::<toml::Table>()
            .is_ok_and(|t| t.contains_key("bdlstm"))
    {
        return Err(run_err(
            run,
            "a BD-LSTM run: it has no PyTorch counterpart to export to",
        ));
    }
    let tmp = temp_sibling(out, "export")?;
    fs::create_dir_all(&tmp).map_err(io_err("create", &tmp))?;
    let result = export_into(run, &tmp, names, config_text, device);
    if result.is_err() {
        // Best effort: what is left of a failed export is ours and incomplete.
        let _ = fs::remove_dir_all(&tmp);
    }
    let exported = result?;
    rename_into_place(&tmp, out)?;
    Ok(exported)
}

fn export_into(run: &Path, tmp: &Path, names: Names, config_text: String, device: &Device) -> Result<Exported> {
    let is_rf = run.join(VAE_RUN_FILE).is_file();
    let copy = |from: &Path, file: &str| -> Result<()> {
        fs::copy(from.join(file), tmp.join(file)).map_err(io_err("copy", from.join(file)))?;
        Ok(())
    };
    let (network, step, tensors, averaged) = if is_rf {
        let rf = load_rf_run(run, device)?;
        if names == Names::AnimateAnyMesh && rf.config.model.scene.any() {
            return Err(run_err(
                run,
                "a scene-aware RF (model.scene): AnimateAnyMesh's MMDiT has no scene parts to name; export it with \
                 --names any4d",
            ));
        }
        let averaged = rf.checkpoint.join(crate::checkpoint::EMA_FILE).is_file();
        let tensors = collect_tensors(&rf.model.mmdit, Network::Mmdit, names);
        let meta = metadata(run, Network::Mmdit, names, config_text, rf.step)?;
        interop::write_file(&tmp.join(MODEL_SAFETENSORS), &tensors, meta.clone()).map_err(interop_err)?;
        let text = collect_tensors(&rf.model.text, Network::Mmdit, Names::Any4d);
        let mut text_meta = meta;
        text_meta.insert(META_NAMES.to_owned(), Names::Any4d.name().to_owned());
        text_meta.insert(META_NETWORK.to_owned(), "text_encoder".to_owned());
        interop::write_file(&tmp.join(TEXT_SAFETENSORS), &text, text_meta).map_err(interop_err)?;
        for f in [TOKENIZER_FILE, VAE_RUN_FILE] {
            copy(&rf.run, f)?;
        }
        (Network::Mmdit, rf.step, tensors.len(), averaged)
    } else {
        let (model, config, ckpt, step) = load_vae_network(run, device)?;
        let averaged = ckpt.join(crate::checkpoint::EMA_FILE).is_file();
        let (network, mut tensors, freqs) = match (&model, &config.model) {
            (AnyMeshVae::Framewise(m), AnyMeshVaeConfig::Framewise(c)) => (
                Network::FrameVae,
                collect_tensors(m, Network::FrameVae, names),
                (c.body.point_freqs, c.offset_freqs),
            ),
            (AnyMeshVae::Sequencewise(m), AnyMeshVaeConfig::Sequencewise(c)) => (
                Network::DyMeshVae,
                collect_tensors(m, Network::DyMeshVae, names),
                (c.body.point_freqs, c.offset_freqs),
            ),
            _ => return Err(run_err(run, "the loaded VAE is not the kind its config names")),
        };
        if names == Names::AnimateAnyMesh {
            // AAM's state_dict also holds two constant buffers; with them the file loads with strict=True.
            for (name, shape, values) in aam_vae_buffers(freqs.0, freqs.1) {
                let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
                tensors.push(FileTensor { name, shape, bytes });
            }
        }
        let meta = metadata(run, network, names, config_text, step)?;
        interop::write_file(&tmp.join(MODEL_SAFETENSORS), &tensors, meta).map_err(interop_err)?;
        if run.join(LATENT_STATS_FILE).is_file() {
            copy(run, LATENT_STATS_FILE)?;
        }
        (network, step, tensors.len(), averaged)
    };
    copy(run, CONFIG_FILE)?;
    Ok(Exported {
        network,
        step,
        tensors,
        averaged,
    })
}

/// What [`import_file`] wrote.
#[derive(Debug)]
pub struct Imported {
    pub network: Network,
    pub names: Names,
    pub step: u64,
    /// Keys of the file ignored as AnimateAnyMesh extras (buffers, CLIP tower).
    pub ignored: usize,
    /// Side files found beside the file and copied into the run.
    pub side_files: Vec<&'static str>,
}

/// Imports `from` (a `model.safetensors` as [`export_run`] writes it, one written by PyTorch, or a PyTorch pickle
/// `.pt`/`.pth`/`.ckpt` read by burn's reader, which runs none of its code) into the new run folder `out`. The network, names and config come from the file's header unless given; `config` is needed for a
/// file without any4d's header. An RF needs its caption encoder, tokenizer and VAE record beside the file (as an
/// export leaves them); a VAE's `latent_stats.json` is copied when it is there.
pub fn import_file(
    from: &Path,
    out: &Path,
    config: Option<&Path>,
    names: Option<Names>,
    device: &Device,
) -> Result<Imported> {
    if out.exists() {
        return Err(run_err(out, "exists; import writes a new folder (remove it first)"));
    }
    // A PyTorch pickle carries no header of any4d's: its config and names are given.
    let meta = match interop::is_pytorch_pickle(from) {
        true => BTreeMap::new(),
        false => interop::read_header_metadata(from).map_err(interop_err)?,
    };
    let config_text = match config {
        Some(p) => fs::read_to_string(p).map_err(io_err("read", p))?,
        None => meta
            .get(META_CONFIG)
            .map(|json| config_from_json(from, json))
            .transpose()?
            .ok_or_else(|| {
                run_err(
                    from,
                    "the file carries no any4d config: give the run config it was trained with (--config)",
                )
            })?,
    };
    let names = match names {
        Some(n) => n,
        None => meta
            .get(META_NAMES)
            .and_then(|n| Names::from_name(n))
            .ok_or_else(|| run_err(from, "the file does not say whose names it uses: give --names"))?,
    };
    // A file without any4d's header (written by PyTorch) is imported as step 0.
    let step: u64 = match meta.get(META_STEP) {
        Some(s) => s
            .parse()
            .map_err(|_| run_err(from, format!("the header's `{META_STEP}` is {s:?}, not a step number")))?,
        None => 0,
    };
    let dir = from
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let config_path = config.map_or_else(|| from.to_path_buf(), Path::to_path_buf);
    let tmp = temp_sibling(out, "import")?;
    let what = Import {
        from,
        dir,
        config_text: &config_text,
        config_path: &config_path,
        meta: &meta,
        names,
        step,
    };
    let result = import_into(&what, &tmp, device);
    if result.is_err() {
        // Best effort: what is left of a failed import is ours and incomplete.
        let _ = fs::remove_dir_all(&tmp);
    }
    let imported = result?;
    rename_into_place(&tmp, out)?;
    Ok(imported)
}

/// The inputs of one import, resolved.
#[derive(Clone, Copy)]
struct Import<'a> {
    from: &'a Path,
    dir: &'a Path,
    config_text: &'a str,
    config_path: &'a Path,
    meta: &'a BTreeMap<String, String>,
    names: Names,
    step: u64,
}

fn import_into(what: &Import, tmp: &Path, device: &Device) -> Result<Imported> {
    let Import {
        from,
        dir,
        config_text,
        config_path,
        meta,
        names,
        step,
    } = *what;
    let table: toml::Table = config_text
        .parse()
        .map_err(|e| run_err(config_path, format!("not TOML: {e}")))?;
    // The network the file says it holds must be the one the config describes, before any tensor is read.
    let described = match table.get("vae").and_then(|v| v.get("kind")).and_then(|k| k.as_str()) {
        _ if table.contains_key("rf") => Network::Mmdit,
        Some("sequencewise") => Network::DyMeshVae,
        _ => Network::FrameVae,
    };
    if let Some(claimed) = meta.get(META_NETWORK).and_then(|n| Network::from_name(n))
        && claimed != described
    {
        return Err(run_err(
            from,
            format!(
                "holds a {} but the config describes a {}",
                claimed.name(),
                described.name()
            ),
        ));
    }
    let ckpt = tmp.join(CHECKPOINTS_DIR).join(step_dir_name(step));
    fs::create_dir_all(&ckpt).map_err(io_err("create", &ckpt))?;
    let mut side_files = Vec::new();
    let (network, report) = if table.contains_key("rf") {
        let rf_config = crate::rf_loop::RfRunConfig::parse(config_text, config_path)?;
        for f in [TOKENIZER_FILE, VAE_RUN_FILE] {
            if !dir.join(f).is_file() {
                return Err(run_err(
                    from,
                    format!("an RF needs `{f}` beside its file (as `any4d model export` writes it)"),
                ));
            }
            fs::copy(dir.join(f), tmp.join(f)).map_err(io_err("copy", dir.join(f)))?;
            side_files.push(f);
        }
        let tokenizer = ScratchTokenizer::load(dir)?;
        let mut model = rf_config.model_config(tokenizer.vocab_size()).init(device);
        let report = interop::read_file(&mut model.mmdit, from, Network::Mmdit, names, &[]).map_err(interop_err)?;
        let text = dir.join(TEXT_SAFETENSORS);
        if !text.is_file() {
            return Err(run_err(
                from,
                format!("an RF needs its caption encoder `{TEXT_SAFETENSORS}` beside its file"),
            ));
        }
        interop::read_file(&mut model.text, &text, Network::Mmdit, Names::Any4d, &[]).map_err(interop_err)?;
        save_params(model, &ckpt.join(MODEL_FILE), Precision::Full)?;
        (Network::Mmdit, report)
    } else {
        let vae_config = VaeRunConfig::parse(config_text, config_path)?;
        let constants = match &vae_config.model {
            AnyMeshVaeConfig::Framewise(c) => aam_vae_buffers(c.body.point_freqs, c.offset_freqs),
            AnyMeshVaeConfig::Sequencewise(c) => aam_vae_buffers(c.body.point_freqs, c.offset_freqs),
        };
        let (network, report) = match vae_config.model.init(device) {
            AnyMeshVae::Framewise(mut m) => {
                let r = interop::read_file(&mut m, from, Network::FrameVae, names, &constants).map_err(interop_err)?;
                save_params(m, &ckpt.join(MODEL_FILE), Precision::Full)?;
                (Network::FrameVae, r)
            }
            AnyMeshVae::Sequencewise(mut m) => {
                let r = interop::read_file(&mut m, from, Network::DyMeshVae, names, &constants).map_err(interop_err)?;
                save_params(m, &ckpt.join(MODEL_FILE), Precision::Full)?;
                (Network::DyMeshVae, r)
            }
        };
        // The statistics belong to the weights an export wrote (its header names their step); beside a file
        // written elsewhere they would describe other weights, so they are not taken.
        if meta.contains_key(META_STEP) && dir.join(LATENT_STATS_FILE).is_file() {
            fs::copy(dir.join(LATENT_STATS_FILE), tmp.join(LATENT_STATS_FILE))
                .map_err(io_err("copy", dir.join(LATENT_STATS_FILE)))?;
            side_files.push(LATENT_STATS_FILE);
        }
        (network, report)
    };
    let state = TrainState {
        step,
        rng: ChaCha8Rng::seed_from_u64(0),
        order: DataOrder::new(0, 1),
        best_valid: None,
    };
    let json = serde_json::to_vec_pretty(&state).map_err(|e| run_err(&ckpt, format!("serialise state: {e}")))?;
    any4d_data::io::write_atomic(&ckpt.join(STATE_FILE), &json)?;
    any4d_data::io::write_atomic(&tmp.join(CONFIG_FILE), config_text.as_bytes())?;
    Ok(Imported {
        network,
        names,
        step,
        ignored: report.ignored.len(),
        side_files,
    })
}

/// Runs the network of the run folder `run` (an RF's MMDiT, or a VAE of either kind) on the probe inputs of `seed`
/// (`any4d_model::probe`) and writes inputs and outputs to the safetensors file `out`, for
/// `scripts/torch_parity.py probe`.
pub fn probe_run(run: &Path, out: &Path, seed: u64, device: &Device) -> Result<Network> {
    let (network, tensors) = if run.join(VAE_RUN_FILE).is_file() {
        let rf = load_rf_run(run, device)?;
        (
            Network::Mmdit,
            any4d_model::probe::probe_mmdit(&rf.model.mmdit, seed, device),
        )
    } else {
        // The network alone: a VAE imported from PyTorch has no latent statistics yet, and a probe needs none.
        let probe = |r: std::result::Result<Vec<FileTensor>, String>| r.map_err(|e| run_err(run, e));
        match load_vae_network(run, device)?.0 {
            AnyMeshVae::Framewise(m) => (
                Network::FrameVae,
                probe(any4d_model::probe::probe_frame_vae(&m, seed, device))?,
            ),
            AnyMeshVae::Sequencewise(m) => (
                Network::DyMeshVae,
                probe(any4d_model::probe::probe_dymesh_vae(&m, seed, device))?,
            ),
        }
    };
    let meta = BTreeMap::from([
        (META_NETWORK.to_owned(), network.name().to_owned()),
        ("any4d.seed".to_owned(), seed.to_string()),
    ]);
    interop::write_file(out, &tensors, meta).map_err(interop_err)?;
    Ok(network)
}

/// A VAE run's network with its newest checkpoint's sampling parameters, its config, that checkpoint and its step;
/// unlike `runs::load_vae_run` it needs no latent statistics (a VAE imported from PyTorch has none yet).
fn load_vae_network(run: &Path, device: &Device) -> Result<(AnyMeshVae, VaeRunConfig, std::path::PathBuf, u64)> {
    let config = VaeRunConfig::parse(
        &fs::read_to_string(run.join(CONFIG_FILE)).map_err(io_err("read", run.join(CONFIG_FILE)))?,
        &run.join(CONFIG_FILE),
    )?;
    let (ckpt, step) = crate::runs::newest_checkpoint(run)?;
    let model = match config.model.init(device) {
        AnyMeshVae::Framewise(m) => AnyMeshVae::Framewise(crate::checkpoint::load_for_sampling(m, &ckpt)?.0),
        AnyMeshVae::Sequencewise(m) => AnyMeshVae::Sequencewise(crate::checkpoint::load_for_sampling(m, &ckpt)?.0),
    };
    Ok((model, config, ckpt, step))
}

/// The run config an export's header carries as JSON, back as TOML text.
fn config_from_json(from: &Path, json: &str) -> Result<String> {
    let value: serde_json::Value = serde_json::from_str(json)
        .map_err(|e| run_err(from, format!("the header's `{META_CONFIG}` is not JSON: {e}")))?;
    toml::to_string(&value).map_err(|e| run_err(from, format!("the header's `{META_CONFIG}` is not a run config: {e}")))
}

/// Renames the finished temporary folder to `out`; if that fails, the temporary folder is removed (best effort: it
/// is ours and would only be left behind).
fn rename_into_place(tmp: &Path, out: &Path) -> Result<()> {
    fs::rename(tmp, out).map_err(|e| {
        let _ = fs::remove_dir_all(tmp);
        io_err("rename into place", out)(e)
    })
}
