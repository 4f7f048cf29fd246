//! VAE training (docs/method.md §3.3–3.5): `any4d train vae`, on one device or data-parallel (`--devices`). Loss
//! (V1)–(V3) from the model crate, the shared loop of `loop_common`, then the latent statistics of
//! docs/method.md §3.4 over the training set, stored next to the VAE checkpoint (`latent_stats.json`). Both the
//! frame-wise VAE and the sequence-wise DyMeshVAE ablation (docs/method.md §8 A3: `vae.kind`) train here.

use std::path::{Path, PathBuf};

use any4d_data::augment::Augment;
use any4d_data::batch::{ClipBatch, ClipBatcher, PadTo};
use any4d_data::io::write_atomic;
use any4d_data::store::{Split, Store, StoredClip};
use any4d_model::any_vae::{AnyMeshVaeConfig, VaeKind};
use any4d_model::latent_stats::{LatentStats, LatentStatsAccumulator};
use any4d_model::mesh_vae::{EdgeList, MeshVae, VaeBatch};
use burn::module::Module;
use burn::prelude::{Device, Int, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::backend;
use crate::config::resolve;
use crate::config::{DeviceConfig, OptimConfig, TrainConfig, to_toml};
use crate::data_order::WholeClips;
use crate::devices::{run_strategy, strategy_note, worker_devices};
use crate::error::{Result, TrainError};
use crate::loop_common::{self, LoopSetup, Losses, Objective, Outcome, RunOptions};
use crate::multi_device::train_data_parallel;
use crate::run_folder::{RunFolder, open_for_resume};

/// File in the VAE run folder with the docs/method.md §3.4 statistics of its final checkpoint.
pub const LATENT_STATS_FILE: &str = "latent_stats.json";

/// The `[vae]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VaeSection {
    /// Which VAE the `[model]` table configures.
    pub kind: VaeKind,
    /// Frames of each clip in a training micro-batch: 0 = all T (docs/method.md §3.5); k ≥ 2 = frame 0 (the
    /// reference) and k − 1 other frames drawn without replacement for each micro-batch. The frame-wise VAE encodes
    /// and decodes frames independently (docs/method.md §3.1), so this trades frames per step for steps per
    /// second; the sequence-wise VAE needs whole clips (0 only). Validation always uses every frame.
    pub train_frames: usize,
    /// FPS tokens P per clip (docs/method.md §2.5: 512): the first P entries of the store's FPS order. Farthest-point
    /// sampling is greedy, so they are exactly the FPS of P points, and one store serves every P up to its own.
    pub tokens: usize,
    /// Training-time augmentation of each example (docs/method.md §2.9); off when absent, as in every paper preset.
    #[serde(default, skip_serializing_if = "Augment::is_off")]
    pub augment: Augment,
    /// Latent statistics (docs/method.md §3.4) from at most this many training windows, evenly strided over the
    /// training list ([`stats_subset`]); 0 = every training window, as in every preset (and in run folders
    /// written before the key). A corpus of 50,000 windows otherwise spends longer on its statistics than the
    /// small preset spends training.
    #[serde(default)]
    pub stats_windows: usize,
    /// Validation on at most this many validation windows, evenly strided ([`stats_subset`]); 0 = all, as in
    /// every preset (and in run folders written before the key).
    #[serde(default)]
    pub valid_windows: usize,
}

/// The windows latent statistics (or validation) are computed from: all of `train` when `cap` is 0 or not smaller,
/// else `cap` of them evenly strided from the first (deterministic, so a run's statistics can be recomputed).
pub fn stats_subset(train: &[usize], cap: usize) -> Vec<usize> {
    if cap == 0 || cap >= train.len() {
        return train.to_vec();
    }
    (0..cap).map(|k| train[k * train.len() / cap]).collect()
}

/// A whole `configs/vae/*.toml` run config.
#[derive(Clone, Debug, PartialEq)]
pub struct VaeRunConfig {
    /// `[vae]`.
    pub vae: VaeSection,
    /// `[model]`: the VAE of `vae.kind`.
    pub model: AnyMeshVaeConfig,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

/// The tables of a VAE run config, `[model]` still untyped until `[vae] kind` says which VAE it describes.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct VaeTables {
    vae: VaeSection,
    model: toml::Table,
    train: TrainConfig,
    optim: OptimConfig,
    device: DeviceConfig,
}

/// Keys of `[model]` that moved into `[model.body]` when the VAE body got its own table.
const BODY_KEYS: [&str; 12] = [
    "width",
    "heads",
    "head_dim",
    "enc_blocks",
    "dec_blocks",
    "latent_channels",
    "point_freqs",
    "ffn_mult",
    "pad_keys",
    "logvar_min",
    "logvar_max",
    "rec_average",
];

/// Reads run folders written before `[model.body]` existed: their `[model]` holds the body's keys flat, and
/// `pad_keys` as `"Masked"` / `"Visible"`; they were trained with the batch form of (V1), so a missing
/// `rec_average` becomes `"batch"`. A table that already has `body` is left alone.
fn migrate_flat_model(model: &mut toml::Table) {
    if model.contains_key("body") || !model.contains_key("width") {
        return;
    }
    let mut body = toml::Table::new();
    for key in BODY_KEYS {
        if let Some(value) = model.remove(key) {
            body.insert(key.to_string(), value);
        }
    }
    if let Some(toml::Value::String(p)) = body.get_mut("pad_keys") {
        *p = p.to_lowercase();
    }
    body.entry("rec_average").or_insert_with(|| "batch".into());
    model.insert("body".into(), toml::Value::Table(body));
}

impl VaeRunConfig {
    /// Parses and validates a resolved VAE run config; unknown or missing keys anywhere are errors naming `file`
    /// and the dotted key.
    pub fn from_table(mut table: toml::Table, file: &Path) -> Result<Self> {
        if let Some(toml::Value::Table(model)) = table.get_mut("model") {
            migrate_flat_model(model);
        }
        let t: VaeTables = resolve::from_table(table, file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason,
        };
        let model = match t.vae.kind {
            VaeKind::Framewise => AnyMeshVaeConfig::Framewise(model_table(t.model, file)?),
            VaeKind::Sequencewise => AnyMeshVaeConfig::Sequencewise(model_table(t.model, file)?),
        };
        match &model {
            AnyMeshVaeConfig::Framewise(c) => c.validate(),
            AnyMeshVaeConfig::Sequencewise(c) => c.validate(),
        }
        .map_err(bad)?;
        t.train.validate(file)?;
        t.optim.validate(file)?;
        let frames_bad = |reason: &str| bad(format!("vae.train_frames = {}: {reason}", t.vae.train_frames));
        if t.vae.tokens == 0 {
            return Err(bad("vae.tokens: P must be positive".into()));
        }
        t.vae.augment.validate("vae.augment").map_err(bad)?;
        match (t.vae.kind, t.vae.train_frames) {
            (_, 0) => {}
            (VaeKind::Sequencewise, _) => return Err(frames_bad("the sequence-wise VAE encodes whole clips; use 0")),
            (VaeKind::Framewise, 1) => {
                return Err(frames_bad(
                    "frame 0 alone has no motion; use 0 (all frames) or at least 2",
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

    crate::config::loading_methods!();

    /// The fully resolved config as TOML (what the run folder stores).
    pub fn to_toml(&self) -> Result<String> {
        let model = match &self.model {
            AnyMeshVaeConfig::Framewise(c) => toml::Table::try_from(c),
            AnyMeshVaeConfig::Sequencewise(c) => toml::Table::try_from(c),
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

/// `[model]` parsed strictly as the VAE config `C`, errors naming `model.…`.
fn model_table<C: serde::de::DeserializeOwned>(model: toml::Table, file: &Path) -> Result<C> {
    let mut wrapped = toml::Table::new();
    wrapped.insert("model".into(), toml::Value::Table(model));
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Wrapped<C> {
        model: C,
    }
    Ok(resolve::from_table::<Wrapped<C>>(wrapped, file)?.model)
}

/// Reads clips `indices` of `store` and stacks them (padded to the batch's largest N_v).
pub fn load_clips(store: &Store, indices: &[usize], device: &Device) -> Result<(ClipBatch, Vec<StoredClip>)> {
    load_augmented(store, indices, None, device)
}

/// [`load_clips`], each clip augmented in order with draws from the generator when one is given
/// (docs/method.md §2.9).
pub fn load_augmented(
    store: &Store,
    indices: &[usize],
    augment: Option<(&Augment, &mut ChaCha8Rng)>,
    device: &Device,
) -> Result<(ClipBatch, Vec<StoredClip>)> {
    let mut items = indices
        .iter()
        .map(|&i| store.get(i))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    if let Some((augment, rng)) = augment {
        for item in &mut items {
            augment.apply(item, rng);
        }
    }
    let batch = ClipBatcher::new(PadTo::BatchMax).try_batch(&items, device)?;
    Ok((batch, items))
}

/// The VAE view of a clip batch with `tokens` FPS tokens (the first ones of the store's FPS order, see
/// [`VaeSection::tokens`]): reference = frame 0 (docs/method.md §1.2).
///
/// # Shapes
/// - `batch.vertices`: `[B, T, N, 3]` → reference `[B, N, 3]`, frames `[B, T, N, 3]`; fps `[B, tokens]`
pub fn vae_batch(batch: &ClipBatch, tokens: usize, device: &Device) -> Result<VaeBatch> {
    let [b, _t, n, _] = batch.vertices.dims();
    let stored = batch.fps.dims()[1];
    if tokens == 0 || tokens > stored {
        return Err(TrainError::Setup(format!(
            "the VAE encodes P = {tokens} FPS tokens per clip, the store holds {stored}: import the clips with --p {tokens} or more"
        )));
    }
    let reference: Tensor<3> = batch.vertices.clone().narrow(1, 0, 1).reshape([b, n, 3]);
    let edges = EdgeList::new(&batch.edges, n, device)?;
    Ok(VaeBatch {
        reference,
        frames: batch.vertices.clone(),
        vmask: batch.vmask.clone(),
        fps: batch.fps.clone().narrow(1, 0, tokens),
        edges,
        noise_seed: None,
    })
}

/// Training objective of a mesh VAE over a store: terms `rec` (V1) and `kl` (V2); total (V3).
pub struct VaeObjective<V> {
    store: Store,
    train: Vec<usize>,
    /// `train` grouped into whole clips: the training examples (docs/method.md §2.6).
    train_clips: WholeClips,
    valid: Vec<usize>,
    micro_batch: usize,
    /// `vae.train_frames` (0 = all).
    train_frames: usize,
    /// `vae.tokens`.
    tokens: usize,
    /// `vae.augment`, applied to training examples only.
    augment: Augment,
    _vae: std::marker::PhantomData<V>,
}

impl<V> VaeObjective<V> {
    /// Serves the train split of the store in `data`, validating on its val split; training micro-batches keep
    /// `vae.train_frames` frames per clip (0 = all; see [`VaeSection::train_frames`]) with `vae.tokens` FPS tokens.
    pub fn new(data: &Path, micro_batch: usize, vae: &VaeSection) -> Result<Self> {
        let (train_frames, tokens) = (vae.train_frames, vae.tokens);
        let store = open_store(data, vae)?;
        let train = store.indices(Split::Train);
        let valid = stats_subset(&store.indices(Split::Val), vae.valid_windows);
        let train_clips = WholeClips::new(store.whole_clips(&train)?);
        Ok(VaeObjective {
            store,
            train,
            train_clips,
            valid,
            micro_batch,
            train_frames,
            tokens,
            augment: vae.augment.clone(),
            _vae: std::marker::PhantomData,
        })
    }
}

/// Opens the store in `data` and checks that its clips have at least `vae.train_frames` frames and `vae.tokens`
/// FPS tokens.
fn open_store(data: &Path, vae: &VaeSection) -> Result<Store> {
    let train_frames = vae.train_frames;
    let store = Store::open(data)?;
    if vae.tokens > store.p() {
        return Err(TrainError::Setup(format!(
            "vae.tokens = {} but the store {} holds {} FPS tokens per clip: import it with --p {} or more",
            vae.tokens,
            data.display(),
            store.p(),
            vae.tokens
        )));
    }
    if train_frames > store.frames() {
        return Err(TrainError::Setup(format!(
            "vae.train_frames = {train_frames} but the store {} holds {}-frame clips",
            data.display(),
            store.frames()
        )));
    }
    Ok(store)
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

impl<V: MeshVae + Module + Clone> Objective for VaeObjective<V> {
    type Model = V;

    fn terms(&self) -> Vec<String> {
        vec!["rec".into(), "kl".into()]
    }

    fn train_len(&self) -> usize {
        self.train_clips.len()
    }

    fn train_blocks(&self) -> Result<Vec<usize>> {
        Ok(self.train_clips.blocks(|pos| self.store.shard_of(self.train[pos]))?)
    }

    fn loss(&self, model: &V, idx: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let ids: Vec<usize> = self
            .train_clips
            .draw(idx, rng)
            .into_iter()
            .map(|w| self.train[w])
            .collect();
        let (mut clips, _) = load_augmented(&self.store, &ids, Some((&self.augment, &mut *rng)), device)?;
        let t = clips.vertices.dims()[1];
        if self.train_frames != 0 && self.train_frames < t {
            let frames = training_frames(t, self.train_frames, rng);
            let frames: Vec<i64> = frames.into_iter().map(|f| f as i64).collect();
            let index = Tensor::<1, Int>::from_data(TensorData::new(frames, [self.train_frames]), device);
            clips.vertices = clips.vertices.select(1, index);
        }
        let mut batch = vae_batch(&clips, self.tokens, device)?;
        batch.noise_seed = Some(rand::RngCore::next_u64(rng)); // ξ from the micro-batch's generator
        let l = model.loss(&batch); // (V1)–(V3)
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
            let l = model.loss(&vae_batch(&clips, self.tokens, device)?);
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
    tokens: usize,
    device: &Device,
) -> Result<LatentStats> {
    let mut acc = LatentStatsAccumulator::new();
    for chunk in indices.chunks(micro_batch.max(1)) {
        let (clips, _) = load_clips(store, chunk, device)?;
        let enc = model.encode_vae_batch(&vae_batch(&clips, tokens, device)?);
        let z = any4d_model::mesh_vae::sample(enc.mu, enc.logvar);
        acc.update(enc.z0, z);
    }
    Ok(acc.finish()?)
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

/// Starts a new VAE run with `cfg`; returns the run folder and the outcome.
pub fn train_vae(cfg: &VaeRunConfig, opts: &RunOptions) -> Result<(RunFolder, Outcome)> {
    // Fail before claiming a run folder when a backend or the store is unusable.
    let devices = worker_devices(&cfg.device, &cfg.train, opts.parallel.as_ref())?;
    check_store_fits(cfg, &open_store(&opts.data, &cfg.vae)?)?;
    let run = RunFolder::create(&opts.runs_dir, &opts.name, &cfg.to_toml()?, &["rec", "kl"])?;
    let outcome = run_vae(cfg, &run, opts, &devices, None)?;
    Ok((run, outcome))
}

/// Continues the VAE run in `run_dir` from its newest checkpoint (config from the run folder; the backend may be
/// overridden, or `opts.parallel` given, whose devices then all run at `[device] precision`).
pub fn resume_vae(run_dir: &Path, backend: Option<backend::Backend>, opts: &RunOptions) -> Result<Outcome> {
    let (run, cfg, ckpt) = open_for_resume(run_dir, VaeRunConfig::parse, backend, |c: &mut VaeRunConfig| {
        &mut c.device
    })?;
    let devices = worker_devices(&cfg.device, &cfg.train, opts.parallel.as_ref())?;
    check_store_fits(&cfg, &open_store(&opts.data, &cfg.vae)?)?;
    run_vae(&cfg, &run, opts, &devices, Some(ckpt))
}

/// Refuses a store this VAE cannot train on before a run folder is claimed: clips of another length than a
/// sequence-wise VAE's trajectories, or a micro-batch too large for the machine ([`check_activations`]).
fn check_store_fits(cfg: &VaeRunConfig, store: &Store) -> Result<()> {
    if let AnyMeshVaeConfig::Sequencewise(m) = &cfg.model
        && m.frames != store.frames()
    {
        return Err(TrainError::Setup(format!(
            "model.frames = {} but the store {} holds {}-frame clips: the sequence-wise VAE encodes whole clips, set \
             model.frames = {}",
            m.frames,
            store.dir().display(),
            store.frames(),
            store.frames()
        )));
    }
    check_activations(cfg, store)
}

/// Refuses a micro-batch whose activation estimate cannot fit this machine (the host's memory for CPU backends),
/// before anything is allocated: the largest clip of the store (bounded from its record size) at `vae.train_frames`
/// frames.
fn check_activations(cfg: &VaeRunConfig, store: &Store) -> Result<()> {
    let frames = match cfg.vae.train_frames {
        0 => store.frames(),
        k => k.min(store.frames()),
    };
    let (micro, n, p) = (cfg.train.micro_batch, store.vertex_bound(), cfg.vae.tokens);
    let estimate = cfg.model.activation_bytes(micro, frames, n, p);
    let host = match cfg.device.backend {
        backend::Backend::Flex | backend::Backend::Ndarray => any4d_model::summary::host_memory_bytes(),
        _ => None,
    };
    let what = format!(
        "a micro-batch of {micro} clips × {frames} frames × up to {n} vertices (P = {p}) at model.body.width {}",
        cfg.model.body().width
    );
    let limit = host.unwrap_or(backend::MAX_ACTIVATION_BYTES);
    any4d_model::summary::check_activation_estimate(&what, estimate, limit).map_err(TrainError::Setup)
}

fn run_vae(
    cfg: &VaeRunConfig,
    run: &RunFolder,
    opts: &RunOptions,
    devices: &[Device],
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    let ad: Vec<Device> = devices.iter().map(|d| d.clone().autodiff()).collect();
    let main = ad
        .first()
        .ok_or_else(|| TrainError::Devices("training needs at least one device".into()))?;
    main.seed(cfg.train.seed);
    match &cfg.model {
        AnyMeshVaeConfig::Framewise(m) => fit(m.init(main), cfg, run, opts, &ad, resume),
        AnyMeshVaeConfig::Sequencewise(m) => fit(m.init(main), cfg, run, opts, &ad, resume),
    }
}

/// Trains `model` on `devices` (autodiff; one, or several with `opts.parallel`'s strategy), then writes the latent
/// statistics of a finished run.
fn fit<V>(
    model: V,
    cfg: &VaeRunConfig,
    run: &RunFolder,
    opts: &RunOptions,
    devices: &[Device],
    resume: Option<PathBuf>,
) -> Result<Outcome>
where
    V: MeshVae + Module + Clone,
    VaeObjective<V>: Sync,
{
    let objective = VaeObjective::<V>::new(&opts.data, cfg.train.micro_batch, &cfg.vae)?;
    run.log(&format!(
        "VAE {:?} on {} ({} train clips in {} windows / {} val clips), backend {}",
        cfg.vae.kind,
        opts.data.display(),
        objective.train_clips.len(),
        objective.train.len(),
        objective.valid.len(),
        cfg.device.backend
    ))?;
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: devices[0].clone(),
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
        init: None,
    };
    let parallel = opts.parallel.as_ref();
    let (model, outcome) = match run_strategy(devices, parallel) {
        Some(strategy) => {
            run.log(&strategy_note(devices, parallel, strategy))?;
            train_data_parallel(&objective, model, setup, devices, strategy)?
        }
        None => loop_common::train(&objective, model, setup)?,
    };
    if let Outcome::Finished { steps, .. } = &outcome {
        let inference = devices[0].clone().without_autodiff();
        inference.seed(cfg.train.seed);
        let stats = latent_stats(
            &model.valid(),
            &objective.store,
            &stats_subset(&objective.train, cfg.vae.stats_windows),
            cfg.train.micro_batch,
            cfg.vae.tokens,
            &inference,
        )?;
        let json = serde_json::to_vec_pretty(&StoredLatentStats { step: *steps, stats })
            .map_err(|e| crate::error::run_err(run.root(), format!("serialise {LATENT_STATS_FILE}: {e}")))?;
        write_atomic(&run.path(LATENT_STATS_FILE), &json)?;
        run.log(&format!(
            "latent statistics (docs/method.md §3.4) of step {steps}: {stats:?}"
        ))?;
    }
    Ok(outcome)
}
