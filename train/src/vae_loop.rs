//! VAE training (docs/method.md §3.3–3.5): `any4d train vae`. Loss (V1)–(V3) from the model crate,
//! the shared loop of `loop_common`, then the latent statistics of docs/method.md §3.4 over the training set, stored
//! next to the VAE checkpoint (`latent_stats.json`). Both the frame-wise VAE and the sequence-wise DyMeshVAE
//! ablation (docs/method.md §8 A3: `vae.kind`) train here.

use std::path::{Path, PathBuf};

use any4d_data::batch::{ClipBatch, ClipBatcher, PadTo};
use any4d_data::store::{Split, Store, StoredClip};
use any4d_model::dymesh_vae::DyMeshVaeConfig;
use any4d_model::frame_vae::{EdgeList, FrameVaeConfig, MeshVaeModel, VaeBatch, VaeEncoding, VaeLoss};
use any4d_model::latent_stats::{LatentStats, LatentStatsAccumulator};
use burn::prelude::{Device, Int, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::backend;
use crate::config::{DeviceConfig, OptimConfig, TrainConfig, parse_strict, strict_model_config, to_toml};
use crate::error::{Result, TrainError, io_err};
use crate::loop_common::{self, LoopSetup, Losses, Objective, Outcome, StopFlag};
use crate::progress::ProgressMode;
use crate::run_folder::{RunFolder, write_atomic};

/// File in the VAE run folder with the docs/method.md §3.4 statistics of its final checkpoint.
pub const LATENT_STATS_FILE: &str = "latent_stats.json";

/// Which mesh VAE (docs/method.md §8 A3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VaeKind {
    /// Frame-wise VAE (docs/method.md §3.2; the method's).
    Framewise,
    /// Sequence-wise DyMeshVAE (AnimateAnyMesh; ablation).
    Sequencewise,
}

/// The `[vae]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VaeSection {
    /// Which VAE the `[model]` table configures.
    pub kind: VaeKind,
    /// Frames of each clip in a training micro-batch: 0 = all T (docs/method.md §3.5); k ≥ 2 = frame 0 (the reference)
    /// and k − 1 other frames drawn without replacement for each micro-batch. The frame-wise VAE encodes and decodes
    /// frames independently (docs/method.md §3.1), so this trades frames per step for steps per second; the
    /// sequence-wise VAE needs whole clips (0 only). Validation always uses every frame.
    pub train_frames: usize,
}

/// The model configuration, by kind.
#[derive(Clone, Debug)]
pub enum VaeModelConfig {
    /// `[model]` of a frame-wise VAE.
    Framewise(FrameVaeConfig),
    /// `[model]` of a DyMeshVAE.
    Sequencewise(DyMeshVaeConfig),
}

/// A whole `configs/vae/*.toml` run config.
#[derive(Clone, Debug)]
pub struct VaeRunConfig {
    /// `[vae]`.
    pub vae: VaeSection,
    /// `[model]`, checked key by key.
    pub model: VaeModelConfig,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct VaeTables {
    vae: VaeSection,
    model: toml::Value,
    train: TrainConfig,
    optim: OptimConfig,
    device: DeviceConfig,
}

impl VaeRunConfig {
    /// Parses and validates a VAE run config; unknown or missing keys anywhere are errors naming `file`.
    pub fn parse(text: &str, file: &Path) -> Result<Self> {
        let t: VaeTables = parse_strict(text, file)?;
        let model = match t.vae.kind {
            VaeKind::Framewise => VaeModelConfig::Framewise(strict_model_config(&t.model, "model", file)?),
            VaeKind::Sequencewise => VaeModelConfig::Sequencewise(strict_model_config(&t.model, "model", file)?),
        };
        t.train.validate(file)?;
        t.optim.validate(file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason: format!("vae.train_frames = {}: {reason}", t.vae.train_frames),
        };
        match (t.vae.kind, t.vae.train_frames) {
            (_, 0) => {}
            (VaeKind::Sequencewise, _) => return Err(bad("the sequence-wise VAE encodes whole clips; use 0".into())),
            (VaeKind::Framewise, 1) => {
                return Err(bad(
                    "frame 0 alone has no motion; use 0 (all frames) or at least 2".into()
                ));
            }
            (VaeKind::Framewise, _) => {}
        }
        Ok(VaeRunConfig {
            vae: t.vae,
            model,
            train: t.train,
            optim: t.optim,
            device: t.device,
        })
    }

    /// Reads a config file.
    pub fn load(file: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(file).map_err(io_err("read config", file))?;
        Self::parse(&text, file)
    }

    /// The fully resolved config as TOML (what the run folder stores).
    pub fn to_toml(&self) -> Result<String> {
        let model = match &self.model {
            VaeModelConfig::Framewise(c) => toml::Value::try_from(c),
            VaeModelConfig::Sequencewise(c) => toml::Value::try_from(c),
        }
        .map_err(|e| TrainError::Config {
            path: "<resolved>".into(),
            reason: e.to_string(),
        })?;
        to_toml(&VaeTables {
            vae: self.vae.clone(),
            model,
            train: self.train.clone(),
            optim: self.optim.clone(),
            device: self.device.clone(),
        })
    }
}

/// The train loops' view of a mesh VAE: [`MeshVaeModel`] under the names the loops use; every model-crate VAE
/// has it.
pub trait MeshVae: MeshVaeModel {
    /// (V1)–(V3) with a posterior sample.
    fn vae_loss(&self, batch: &VaeBatch) -> VaeLoss {
        self.loss(batch)
    }
    /// Encoder outputs.
    fn vae_encode(&self, batch: &VaeBatch) -> VaeEncoding {
        self.encode_vae_batch(batch)
    }
}

impl<V: MeshVaeModel> MeshVae for V {}

/// Reads clips `indices` of `store` and stacks them (padded to the batch's largest N_v).
pub fn load_clips(store: &Store, indices: &[usize], device: &Device) -> Result<(ClipBatch, Vec<StoredClip>)> {
    let items = indices
        .iter()
        .map(|&i| store.get(i).map_err(|e| TrainError::Other(e.to_string())))
        .collect::<Result<Vec<_>>>()?;
    let batch = ClipBatcher::new(PadTo::BatchMax)
        .try_batch(&items, device)
        .map_err(|e| TrainError::Other(e.to_string()))?;
    Ok((batch, items))
}

/// The VAE view of a clip batch: reference = frame 0 (docs/method.md §1.2).
///
/// # Shapes
/// - `batch.vertices`: `[B, T, N, 3]` → reference `[B, N, 3]`, frames `[B, T, N, 3]`
pub fn vae_batch(batch: &ClipBatch, device: &Device) -> Result<VaeBatch> {
    let [b, _t, n, _] = batch.vertices.dims();
    let reference: Tensor<3> = batch.vertices.clone().narrow(1, 0, 1).reshape([b, n, 3]);
    let edges = EdgeList::new(&batch.edges, n, device).map_err(|e| TrainError::Other(e.to_string()))?;
    Ok(VaeBatch {
        reference,
        frames: batch.vertices.clone(),
        vmask: batch.vmask.clone(),
        fps: batch.fps.clone(),
        edges,
    })
}

/// Training objective of a mesh VAE over a store: terms `rec` (V1) and `kl` (V2); total (V3).
pub struct VaeObjective<V> {
    store: Store,
    train: Vec<usize>,
    valid: Vec<usize>,
    micro_batch: usize,
    /// `vae.train_frames` (0 = all).
    train_frames: usize,
    _vae: std::marker::PhantomData<V>,
}

impl<V> VaeObjective<V> {
    /// Serves the train split of the store in `data`, validating on its val split; training micro-batches keep
    /// `train_frames` frames per clip (0 = all; see [`VaeSection::train_frames`]).
    pub fn new(data: &Path, micro_batch: usize, train_frames: usize) -> Result<Self> {
        let store = open_store(data, train_frames)?;
        let train = store.indices(Split::Train);
        let valid = store.indices(Split::Val);
        Ok(VaeObjective {
            store,
            train,
            valid,
            micro_batch,
            train_frames,
            _vae: std::marker::PhantomData,
        })
    }
}

/// Opens the store in `data` and checks that its clips have at least `train_frames` frames.
fn open_store(data: &Path, train_frames: usize) -> Result<Store> {
    let store = Store::open(data).map_err(|e| TrainError::Other(format!("{}: {e}", data.display())))?;
    if train_frames > store.frames() {
        return Err(TrainError::Other(format!(
            "vae.train_frames = {train_frames} but the store {} holds {}-frame clips",
            data.display(),
            store.frames()
        )));
    }
    Ok(store)
}

/// Fails before a run folder is claimed when the store in `data` cannot serve `cfg`.
pub(crate) fn check_store(cfg: &VaeRunConfig, data: &Path) -> Result<()> {
    open_store(data, cfg.vae.train_frames).map(|_| ())
}

/// Frame 0 and `k − 1` distinct frames of `1..t` in increasing order, drawn from `rng`; all `t` frames when `k` is
/// 0 or at least `t`.
pub fn training_frames(t: usize, k: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    if k == 0 || k >= t {
        return (0..t).collect();
    }
    let mut rest = rand::seq::index::sample(rng, t - 1, k - 1).into_vec();
    rest.sort_unstable();
    std::iter::once(0).chain(rest.into_iter().map(|f| f + 1)).collect()
}

impl<V: MeshVae> Objective for VaeObjective<V> {
    type Model = V;

    fn terms(&self) -> Vec<String> {
        vec!["rec".into(), "kl".into()]
    }

    fn train_len(&self) -> usize {
        self.train.len()
    }

    fn loss(&self, model: &V, idx: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let ids: Vec<usize> = idx.iter().map(|&i| self.train[i]).collect();
        let (mut clips, _) = load_clips(&self.store, &ids, device)?;
        let t = clips.vertices.dims()[1];
        if self.train_frames != 0 && self.train_frames < t {
            let frames = training_frames(t, self.train_frames, rng);
            let frames: Vec<i64> = frames.into_iter().map(|f| f as i64).collect();
            let index = Tensor::<1, Int>::from_data(TensorData::new(frames, [self.train_frames]), device);
            clips.vertices = clips.vertices.select(1, index);
        }
        let l = model.vae_loss(&vae_batch(&clips, device)?); // (V1)–(V3)
        Ok(Losses {
            total: l.total,
            terms: vec![l.rec, l.kl],
        })
    }

    fn validate(&self, model: &V, device: &Device, _step: u64) -> Result<Option<Vec<f64>>> {
        if self.valid.is_empty() {
            return Ok(None);
        }
        let mut sums = [0.0f64; 3];
        for chunk in self.valid.chunks(self.micro_batch) {
            let (clips, _) = load_clips(&self.store, chunk, device)?;
            let l = model.vae_loss(&vae_batch(&clips, device)?);
            let w = chunk.len() as f64 / self.valid.len() as f64;
            for (s, t) in sums.iter_mut().zip([l.rec, l.kl, l.total]) {
                *s += w * loop_common::scalar(t);
            }
        }
        Ok(Some(sums.to_vec()))
    }
}

/// docs/method.md §3.4: global mean/std of z₀ and of posterior-sampled trajectory latents over `indices` of `store`.
pub fn latent_stats<V: MeshVae>(
    model: &V,
    store: &Store,
    indices: &[usize],
    micro_batch: usize,
    device: &Device,
) -> Result<LatentStats> {
    let mut acc = LatentStatsAccumulator::new();
    for chunk in indices.chunks(micro_batch.max(1)) {
        let (clips, _) = load_clips(store, chunk, device)?;
        let enc = model.vae_encode(&vae_batch(&clips, device)?);
        let z = any4d_model::frame_vae::sample(enc.mu, enc.logvar);
        acc.update(enc.z0, z);
    }
    acc.finish().map_err(|e| TrainError::Other(e.to_string()))
}

/// `latent_stats.json`: the statistics and the VAE checkpoint step they belong to.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredLatentStats {
    /// Checkpoint step of the VAE that produced them.
    pub step: u64,
    /// The statistics.
    pub stats: LatentStats,
}

/// Options of `any4d train vae` besides the config.
pub struct VaeRunOptions {
    /// Store folder (`--data`).
    pub data: PathBuf,
    /// Folder that holds run folders (`runs/`).
    pub runs_dir: PathBuf,
    /// Run name (`--run`), default "vae".
    pub name: String,
    /// Progress display.
    pub progress: ProgressMode,
    /// Ctrl-C flag.
    pub stop: StopFlag,
}

/// Starts a new VAE run with `cfg`; returns the run folder and the outcome.
pub fn train_vae(cfg: &VaeRunConfig, opts: &VaeRunOptions) -> Result<(RunFolder, Outcome)> {
    // Fail before claiming a run folder when the backend or the store is unusable.
    backend::check(cfg.device.backend, cfg.device.precision)?;
    check_store(cfg, &opts.data)?;
    let run = RunFolder::create(&opts.runs_dir, &opts.name, &cfg.to_toml()?, &["rec", "kl"])?;
    let outcome = run_vae(cfg, &run, opts, None)?;
    Ok((run, outcome))
}

/// Continues the VAE run in `run_dir` from its newest checkpoint (config from the run folder; the backend may
/// be overridden).
pub fn resume_vae(run_dir: &Path, backend: Option<backend::Backend>, opts: &VaeRunOptions) -> Result<Outcome> {
    let run = RunFolder::open(run_dir)?;
    let mut cfg = VaeRunConfig::parse(&run.config_text()?, &run.path(crate::run_folder::CONFIG_FILE))?;
    if let Some(b) = backend {
        cfg.device.backend = b;
    }
    let ckpt = crate::checkpoint::latest(&run.path(crate::run_folder::CHECKPOINTS_DIR))?.ok_or_else(|| {
        TrainError::Checkpoint {
            path: run_dir.to_path_buf(),
            reason: "no complete checkpoint to resume".into(),
        }
    })?;
    run_vae(&cfg, &run, opts, Some(ckpt))
}

fn run_vae(cfg: &VaeRunConfig, run: &RunFolder, opts: &VaeRunOptions, resume: Option<PathBuf>) -> Result<Outcome> {
    let device = backend::device(cfg.device.backend, cfg.device.precision)?;
    let ad = device.clone().autodiff();
    ad.seed(cfg.train.seed);
    match &cfg.model {
        VaeModelConfig::Framewise(m) => fit(m.init(&ad), cfg, run, opts, resume, &ad),
        VaeModelConfig::Sequencewise(m) => fit(m.init(&ad), cfg, run, opts, resume, &ad),
    }
}

fn fit<V: MeshVae>(
    model: V,
    cfg: &VaeRunConfig,
    run: &RunFolder,
    opts: &VaeRunOptions,
    resume: Option<PathBuf>,
    device: &Device,
) -> Result<Outcome> {
    let objective = VaeObjective::<V>::new(&opts.data, cfg.train.micro_batch, cfg.vae.train_frames)?;
    run.log(&format!(
        "VAE {:?} on {} ({} train / {} val clips), backend {}",
        cfg.vae.kind,
        opts.data.display(),
        objective.train.len(),
        objective.valid.len(),
        cfg.device.backend
    ))?;
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: device.clone(),
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
    };
    let (model, outcome) = loop_common::train(&objective, model, setup)?;
    if let Outcome::Finished { steps, .. } = &outcome {
        let inference = device.clone().without_autodiff();
        inference.seed(cfg.train.seed);
        let stats = latent_stats(
            &model.valid(),
            &objective.store,
            &objective.train,
            cfg.train.micro_batch,
            &inference,
        )?;
        let json = serde_json::to_vec_pretty(&StoredLatentStats { step: *steps, stats })
            .map_err(|e| TrainError::Other(format!("serialise latent stats: {e}")))?;
        write_atomic(&run.path(LATENT_STATS_FILE), &json)?;
        run.log(&format!("latent statistics (docs/method.md §3.4) of step {steps}: {stats:?}"))?;
    }
    Ok(outcome)
}
