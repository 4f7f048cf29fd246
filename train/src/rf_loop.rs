//! Rectified-flow training (SPEC §4.2, §4.4–4.7, §5.4; issue 5 item 1): `any4d train rf`. The frozen VAE of
//! `--vae RUN` encodes the clips (posterior μ, log σ², z₀) — once at run start into host memory, or per
//! micro-batch (`rf.latent_cache`); each step draws z = μ + σξ (or μ), standardizes it (SPEC §3.4), draws keyframe
//! masks (§4.5, §5.4; SceneMI's noisy keyframes for `impute_until` are noised in vertex space and encoded per
//! batch), τ, ε and the CFG text dropout, and minimises (R5) through `rf_training_loss`. The caption encoder is the
//! `scratch` one: its tokenizer is trained on the TRAIN captions at run start (`tokenizer.json` in the run folder)
//! and its transformer is trained jointly with the MMDiT ([`RfModel`]). Run config: `configs/rf/*.toml`
//! (`[model]`, `[rf]`, `[text]`, `[train]`, `[optim]`, `[device]`).
//!
//! Validation (issue 5 item 4): (R5) on the VAL split at every validation (`valid.csv`) and, every
//! `rf.valid_sample_every` steps and at the end, a few VAL clips completed by the current network through the eval
//! crate's [`RfSampler`] (SPEC §4.6) and scored with (E1)–(E3) of SPEC §6 (`samples.csv`, see
//! [`RfObjective::validation_samples`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use any4d_data::batch::PadTo;
use any4d_data::keyframes::{KeyframeStrategy, sample_keyframes};
use any4d_data::store::{Split, Store};
use any4d_eval::learned::{LearnedModels, MeshCodec, MeshVae as CodecVae, RfSampler};
use any4d_eval::methods::{KeyframeNoise, MethodKind, RfMethod, complete_and_score};
use any4d_model::frame_vae::{self, FrameVae};
use any4d_model::latent_stats::LatentStats;
use any4d_model::mmdit::{KfMode, Mmdit, MmditConfig};
use any4d_model::rectified_flow::{KeyframeLoss, RfBatch, RfLossOptions, SampleOptions, TauSampler, rf_training_loss};
use any4d_model::text::scratch::{ScratchTextConfig, ScratchTextModel, ScratchTokenizer};
use any4d_model::text::{TextBatch, TextEncoder, TextError};
use burn::module::Module;
use burn::prelude::{Device, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::backend;
use crate::config::{DeviceConfig, OptimConfig, TrainConfig, parse_strict, to_toml};
use crate::error::{Result, TrainError, io_err};
use crate::loop_common::{self, LoopSetup, Losses, Objective, Outcome, StopFlag};
use crate::multi_device::{Parallel, train_data_parallel};
use crate::progress::ProgressMode;
use crate::run_folder::{CHECKPOINTS_DIR, CONFIG_FILE, RunFolder, SAMPLES_FILE};
use crate::runs::{self, LoadedVae, VaeRunRecord};
use crate::vae_loop::{MeshVae, load_clips, vae_batch};

/// Names of the loss terms in `metrics.csv` / `valid.csv`: (R5) and the fraction of keyframe slots (m = 1).
pub const RF_TERMS: [&str; 2] = ["rf", KF_FRAC_TERM];

/// The RF's diagnostic `metrics.csv` column: the fraction of latent frames that are keyframes (not a loss).
pub const KF_FRAC_TERM: &str = "kf_frac";

/// Columns of `samples.csv` after `step`: (E1) RMSE, (E2) Chamfer, (E3) centroid DTW of SPEC §6, means over the
/// sampled VAL clips.
pub const SAMPLE_TERMS: [&str; 3] = ["rmse", "chamfer", "dtw"];

/// Keyframes of the validation samples: frames 0 and T − 1 and one interior frame (SPEC §6.1's protocol with
/// K_x = 1), drawn once per clip from a fixed seed.
pub const VALID_SAMPLE_KEYFRAMES: KeyframeStrategy = KeyframeStrategy::FirstLastPlus(1);

/// How the keyframe set of a training sample is drawn (SPEC §4.5, §5.4, §8 X3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KfSampler {
    /// k ~ Unif{0..=k_max}, a uniform k-subset of the T frames (paper, k_max = 5).
    Random,
    /// SceneMI: k ~ Unif{2..=T}, first and last always included.
    Scenemi,
}

/// Which VAE latent trains the RF (SPEC §3.4: statistics over posterior samples).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentDraw {
    /// z = μ + σξ, a fresh posterior sample every time a clip enters a batch.
    Sample,
    /// z = μ.
    Mean,
}

/// Where the frozen-VAE latents live during training.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LatentCache {
    /// Encode every clip once at run start and keep z₀, μ and log σ² in host memory: P·C·(1 + 2T) floats per clip
    /// (811 KB at the paper's P = 512, C = 12, T = 16, so about 169 GB for 208K clips).
    Memory,
    /// Encode each micro-batch with the frozen VAE when it is drawn: no memory, one VAE forward per batch.
    PerBatch,
}

/// The `[rf]` table: options of the RF objective.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfSection {
    /// Keyframe sampler in training.
    pub kf_sampler: KfSampler,
    /// Largest k of the random sampler (SPEC §4.5: 5).
    pub k_max: usize,
    /// τ distribution (SPEC §4.5 step 4: uniform; AAM: cosmap).
    pub tau_sampler: TauSampler,
    /// Which slots enter (R5) (SPEC §4.2: all).
    pub keyframe_loss: KeyframeLoss,
    /// τ* of (R9) for `kf_mode = "impute_until"` (SPEC §5.4: 0.98).
    pub tau_star: f64,
    /// Std of the keyframe vertex noise per unit l ~ U(0, 1) for `impute_until` (SPEC §5.4: 0.02).
    pub keyframe_noise: f64,
    /// Probability of dropping the caption for CFG (SPEC §4.4: 0.1).
    pub text_dropout: f64,
    /// Posterior sample or mean as the RF's target latent.
    pub latent: LatentDraw,
    /// Frozen-VAE latents cached in memory or encoded per batch.
    pub latent_cache: LatentCache,
    /// Validation sampling (issue 5 item 4) at every validation whose step is a multiple of this, and at the
    /// last step; 0 = off. A multiple of `train.valid_every`.
    pub valid_sample_every: u64,
    /// VAL clips sampled (the first ones in store order, the same every time).
    pub valid_sample_clips: usize,
    /// Grid points over [0, 1] of the validation sampler (SPEC §4.6: 64, midpoint solver).
    pub valid_sample_grid: usize,
}

/// Which caption encoder the RF trains with (SPEC §4.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextEncoderKind {
    /// WordPiece tokenizer trained on the TRAIN captions + a small transformer trained jointly with the RF.
    /// (The CLIP and BERT loaders of the model crate are not wired into training yet.)
    Scratch,
}

/// The `[text]` table: the caption encoder. Its width is `model.text_dim`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextSection {
    /// Encoder kind.
    pub encoder: TextEncoderKind,
    /// Largest tokenizer vocabulary (special tokens included); the trained one may be smaller.
    pub vocab_size: usize,
    /// Transformer layers.
    pub layers: usize,
    /// Attention heads; must divide `model.text_dim`.
    pub heads: usize,
    /// Tokens L per caption (SPEC §1.1: 77).
    pub max_len: usize,
}

/// A whole `configs/rf/*.toml` run config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RfRunConfig {
    /// `[model]`: the MMDiT (strict serde struct of the model crate).
    pub model: MmditConfig,
    /// `[rf]`.
    pub rf: RfSection,
    /// `[text]`.
    pub text: TextSection,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

impl RfRunConfig {
    /// Parses and validates an RF run config; unknown or missing keys anywhere are errors naming `file`.
    pub fn parse(text: &str, file: &Path) -> Result<Self> {
        let cfg: RfRunConfig = parse_strict(text, file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason,
        };
        cfg.model.validate().map_err(bad)?;
        cfg.train.validate(file)?;
        cfg.optim.validate(file)?;
        let rf = &cfg.rf;
        if !(0.0..=1.0).contains(&rf.text_dropout) {
            return Err(bad(format!("rf.text_dropout {} is outside [0, 1]", rf.text_dropout)));
        }
        if !(0.0..=1.0).contains(&rf.tau_star) {
            return Err(bad(format!("rf.tau_star {} is outside [0, 1]", rf.tau_star)));
        }
        if !(rf.keyframe_noise >= 0.0 && rf.keyframe_noise.is_finite()) {
            return Err(bad(format!(
                "rf.keyframe_noise {} must be finite and non-negative",
                rf.keyframe_noise
            )));
        }
        if rf.k_max > cfg.model.frames {
            return Err(bad(format!(
                "rf.k_max {} exceeds model.frames {}",
                rf.k_max, cfg.model.frames
            )));
        }
        if rf.kf_sampler == KfSampler::Scenemi && cfg.model.frames < 2 {
            return Err(bad(format!(
                "rf.kf_sampler = \"scenemi\" keeps the first and last frames: needs model.frames ≥ 2, got {}",
                cfg.model.frames
            )));
        }
        if rf.valid_sample_every > 0 {
            if !rf.valid_sample_every.is_multiple_of(cfg.train.valid_every) {
                return Err(bad(format!(
                    "rf.valid_sample_every {} must be a multiple of train.valid_every {} (samples are drawn at \
                     validations), or 0 for off",
                    rf.valid_sample_every, cfg.train.valid_every
                )));
            }
            if rf.valid_sample_clips == 0 {
                return Err(bad("rf.valid_sample_clips must be positive when sampling is on".into()));
            }
            if rf.valid_sample_grid < 2 {
                return Err(bad(format!(
                    "rf.valid_sample_grid {} must be at least 2",
                    rf.valid_sample_grid
                )));
            }
            VALID_SAMPLE_KEYFRAMES
                .check(cfg.model.frames)
                .map_err(|e| bad(format!("rf.valid_sample_every > 0 needs model.frames ≥ 3: {e}")))?;
        }
        let t = &cfg.text;
        for (name, value) in [
            ("vocab_size", t.vocab_size),
            ("layers", t.layers),
            ("heads", t.heads),
            ("max_len", t.max_len),
        ] {
            if value == 0 {
                return Err(bad(format!("text.{name} must be positive, got 0")));
            }
        }
        if !cfg.model.text_dim.is_multiple_of(t.heads) {
            return Err(bad(format!(
                "text.heads ({}) must divide model.text_dim ({})",
                t.heads, cfg.model.text_dim
            )));
        }
        Ok(cfg)
    }

    /// Reads a config file.
    pub fn load(file: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(file).map_err(io_err("read config", file))?;
        Self::parse(&text, file)
    }

    /// The fully resolved config as TOML.
    pub fn to_toml(&self) -> Result<String> {
        to_toml(self)
    }

    /// The network of this config for a trained tokenizer of `vocab_size` tokens.
    pub fn model_config(&self, vocab_size: usize) -> RfModelConfig {
        RfModelConfig {
            mmdit: self.model.clone(),
            text: ScratchTextConfig {
                vocab_size,
                width: self.model.text_dim,
                layers: self.text.layers,
                heads: self.text.heads,
                max_len: self.text.max_len,
            },
        }
    }

    /// The options of (R5) for this config.
    pub fn loss_options(&self) -> RfLossOptions {
        RfLossOptions {
            kf_mode: self.model.kf_mode,
            keyframe_loss: self.rf.keyframe_loss,
            tau_star: self.rf.tau_star,
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// The trained network

/// Sizes of [`RfModel`].
#[derive(Clone, Debug, PartialEq)]
pub struct RfModelConfig {
    /// The MMDiT.
    pub mmdit: MmditConfig,
    /// The scratch caption transformer (width = `mmdit.text_dim`).
    pub text: ScratchTextConfig,
}

impl RfModelConfig {
    /// Builds both networks on `device`.
    pub fn init(&self, device: &Device) -> RfModel {
        RfModel {
            mmdit: self.mmdit.init(device),
            text: self.text.init(device),
        }
    }
}

/// What the RF run trains: the MMDiT v_θ (R4) and, jointly, the scratch caption encoder (SPEC §4.4).
#[derive(Module, Debug)]
pub struct RfModel {
    /// The keyframe-conditioned velocity network.
    pub mmdit: Mmdit,
    /// The caption transformer feeding the MMDiT's text stream.
    pub text: ScratchTextModel,
}

impl RfModel {
    /// Token states of `captions` (empty or blank caption = all padding = zero states, unconditional).
    ///
    /// # Shapes
    /// - output: `[B, L, D_txt]` with B = `captions.len()`, L = `max_len`
    pub fn encode_text(
        &self,
        tokenizer: &ScratchTokenizer,
        captions: &[String],
        max_len: usize,
        device: &Device,
    ) -> Result<Tensor<3>> {
        let ids = tokenizer
            .pad_batch(captions, max_len)
            .map_err(|e| TrainError::Other(e.to_string()))?;
        Ok(self.text.forward(ids.ids_tensor(device), ids.pad_tensor(device)))
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Keyframe masks (SPEC §4.5, §5.4)

/// The keyframe mask m of one training window of `frames` frames (true = observed keyframe): `Random` draws
/// k ~ U{0..=k_max} and a uniform k-subset (§4.5 steps 1–2); `Scenemi` draws k ~ U{2..=T} with the first and last
/// frames always included (§5.4). Modes trained without keyframes (`replace_noised`, `none`) get all-false masks
/// and consume no random numbers.
pub fn draw_keyframe_mask(rf: &RfSection, kf_mode: KfMode, frames: usize, rng: &mut impl Rng) -> Vec<bool> {
    if !kf_mode.has_mask_channels() {
        return vec![false; frames];
    }
    match rf.kf_sampler {
        KfSampler::Random => sample_keyframes(&KeyframeStrategy::Random { k_max: rf.k_max }, frames, rng),
        KfSampler::Scenemi => {
            let mut mask = vec![false; frames];
            mask[0] = true;
            mask[frames - 1] = true;
            let k = rng.random_range(2..=frames);
            let mut inner: Vec<usize> = (1..frames - 1).collect();
            let (chosen, _) = inner.partial_shuffle(rng, k - 2);
            for &f in chosen.iter() {
                mask[f] = true;
            }
            mask
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Frozen-VAE latents

/// Frozen-VAE encoding of one clip, kept in host memory in the VAE's layout.
#[derive(Clone, Debug)]
pub struct ClipLatents {
    /// Index of the clip in the store.
    pub store_index: usize,
    /// Its caption.
    pub caption: String,
    /// Shape latent z₀, `[P, C]` row-major.
    pub z0: Vec<f32>,
    /// Posterior mean μ_f of every frame, `[T, P, C]` row-major.
    pub mu: Vec<f32>,
    /// Posterior log σ²_f, `[T, P, C]` row-major.
    pub logvar: Vec<f32>,
}

/// The latents of one split and their sizes.
#[derive(Clone, Debug)]
pub struct LatentSet {
    /// One entry per clip, in store order.
    pub clips: Vec<ClipLatents>,
    /// T.
    pub frames: usize,
    /// P.
    pub tokens: usize,
    /// C.
    pub channels: usize,
}

impl LatentSet {
    /// Host bytes held.
    pub fn bytes(&self) -> usize {
        self.clips.len() * self.tokens * self.channels * (1 + 2 * self.frames) * std::mem::size_of::<f32>()
    }
}

fn host_f32<const D: usize>(t: Tensor<D>, what: &str) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| TrainError::Other(format!("{what}: cannot read tensor data: {e:?}")))
}

/// Encodes clips `store_indices` of `store` with the frozen frame-wise VAE, `micro_batch` clips at a time.
pub fn encode_latents(
    vae: &FrameVae,
    store: &Store,
    store_indices: &[usize],
    micro_batch: usize,
    device: &Device,
) -> Result<LatentSet> {
    let (frames, tokens) = (store.frames(), store.p());
    let mut clips = Vec::with_capacity(store_indices.len());
    let mut channels = 0;
    for chunk in store_indices.chunks(micro_batch.max(1)) {
        let (batch, _) = load_clips(store, chunk, device)?;
        let enc = vae.vae_encode(&vae_batch(&batch, device)?);
        let [b, t, p, c] = enc.mu.dims();
        if (t, p) != (frames, tokens) {
            return Err(TrainError::Other(format!(
                "VAE latents are [{b}, {t}, {p}, {c}], the store {} has T = {frames}, P = {tokens}",
                store.dir().display()
            )));
        }
        channels = c;
        let z0 = host_f32(enc.z0, "z0")?;
        let mu = host_f32(enc.mu, "mu")?;
        let logvar = host_f32(enc.logvar, "logvar")?;
        let (shape_len, motion_len) = (p * c, t * p * c);
        for (i, (&store_index, caption)) in chunk.iter().zip(batch.captions).enumerate() {
            clips.push(ClipLatents {
                store_index,
                caption,
                z0: z0[i * shape_len..(i + 1) * shape_len].to_vec(),
                mu: mu[i * motion_len..(i + 1) * motion_len].to_vec(),
                logvar: logvar[i * motion_len..(i + 1) * motion_len].to_vec(),
            });
        }
    }
    Ok(LatentSet {
        clips,
        frames,
        tokens,
        channels,
    })
}

// ---------------------------------------------------------------------------------------------------------------
// The objective

/// Whether a batch applies the CFG caption dropout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextDropout {
    /// keep_txt ~ Bernoulli(1 − rf.text_dropout) (training).
    Apply,
    /// keep_txt = 1 (validation).
    Off,
}

/// Which split a batch is drawn from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subset {
    /// The TRAIN split.
    Train,
    /// The VAL split.
    Valid,
}

/// One RF batch with the noise and times of (R1).
pub struct RfStep {
    /// Standardized latents, keyframe mask, text.
    pub batch: RfBatch,
    /// ε ~ N(0, I), `[B, P, T, C]`.
    pub eps: Tensor<4>,
    /// τ per sample, `[B]`.
    pub tau: Tensor<1>,
}

/// The clips of one split: their store indices and, with [`LatentCache::Memory`], their latents.
struct SplitLatents {
    store_indices: Vec<usize>,
    cached: Option<LatentSet>,
}

/// Training objective of the keyframe RF on a frozen VAE: terms `rf` (R5) and `kf_frac`.
pub struct RfObjective {
    cfg: RfRunConfig,
    stats: LatentStats,
    tokenizer: Arc<ScratchTokenizer>,
    vae: FrameVae,
    store: Store,
    train: SplitLatents,
    valid: SplitLatents,
    /// Where validation samples are logged ([`RfObjective::log_validation_samples`]).
    samples_run: Option<RunFolder>,
}

/// Mean scores of one validation-sampling round (SPEC §6 (E1)–(E3), normalised frame of each clip's frame 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidSampleScores {
    /// VAL clips sampled.
    pub clips: usize,
    /// (E1) vertex RMSE on the non-keyframes.
    pub rmse: f64,
    /// (E2) Chamfer distance.
    pub chamfer: f64,
    /// (E3) centroid-trajectory DTW.
    pub dtw: f64,
}

/// The scratch caption encoder during training, as the eval crate's [`TextEncoder`]: the objective's tokenizer
/// (shared, not copied) and the text transformer of the current network.
struct TrainingText {
    tokenizer: Arc<ScratchTokenizer>,
    model: ScratchTextModel,
    max_len: usize,
    dim: usize,
}

impl TextEncoder for TrainingText {
    fn encode(&self, captions: &[String], device: &Device) -> std::result::Result<TextBatch, TextError> {
        let ids = self.tokenizer.pad_batch(captions, self.max_len)?;
        let pad_mask = ids.pad_tensor(device);
        let states = self.model.forward(ids.ids_tensor(device), pad_mask.clone());
        Ok(TextBatch { states, pad_mask })
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn max_len(&self) -> usize {
        self.max_len
    }
}

impl RfObjective {
    /// Checks that the RF config fits the VAE and the store in `data`; with [`LatentCache::Memory`] encodes the
    /// TRAIN and VAL clips once with the frozen VAE (on the inference `device`).
    pub fn new(
        cfg: &RfRunConfig,
        data: &Path,
        vae: &LoadedVae,
        tokenizer: ScratchTokenizer,
        device: &Device,
    ) -> Result<Self> {
        let store = open_store(data)?;
        check_compatible(cfg, &store, vae)?;
        let frame_vae = vae.frame_vae()?.clone();
        let split = |split: Split| -> Result<SplitLatents> {
            let store_indices = store.indices(split);
            let cached = match cfg.rf.latent_cache {
                LatentCache::Memory => Some(encode_latents(
                    &frame_vae,
                    &store,
                    &store_indices,
                    cfg.train.micro_batch,
                    device,
                )?),
                LatentCache::PerBatch => None,
            };
            Ok(SplitLatents { store_indices, cached })
        };
        let (train, valid) = (split(Split::Train)?, split(Split::Val)?);
        Ok(RfObjective {
            cfg: cfg.clone(),
            stats: vae.stats,
            tokenizer: Arc::new(tokenizer),
            vae: frame_vae,
            store,
            train,
            valid,
            samples_run: None,
        })
    }

    /// Turns on validation sampling into `run` when `rf.valid_sample_every` > 0: creates `samples.csv`
    /// (`step, rmse, chamfer, dtw`) unless a resumed run already has it; from then on every validation at a
    /// multiple of `rf.valid_sample_every` or at the last step appends a row of [`RfObjective::validation_samples`]
    /// and a line to `log.txt`. With `valid_sample_every = 0` nothing is written.
    pub fn log_validation_samples(&mut self, run: &RunFolder) -> Result<()> {
        if self.cfg.rf.valid_sample_every == 0 {
            return Ok(());
        }
        run.ensure_table(SAMPLES_FILE, &SAMPLE_TERMS)?;
        self.samples_run = Some(run.clone());
        Ok(())
    }

    /// Completes the first `rf.valid_sample_clips` VAL clips with `model` (inference mode, on the inference
    /// `device`) and scores them: keyframes [`VALID_SAMPLE_KEYFRAMES`] from a fixed seed, the eval crate's
    /// [`RfSampler`] on an `rf.valid_sample_grid`-point midpoint grid with CFG weight 1 (SPEC §4.6: (R3) for
    /// `input_mask`, the replacement sampler (R7)–(R8) for `replace_noised` and `none`, (R9) with `rf.tau_star`
    /// for `impute_until`), keyframes replaced by the ground truth, then (E1)–(E3) of SPEC §6 against the clip.
    /// Every draw is seeded from `train.seed`, so the same network gives the same scores; the training RNG
    /// streams are untouched (the loop reseeds the device before every step). `None` without VAL clips.
    pub fn validation_samples(&self, model: &RfModel, device: &Device) -> Result<Option<ValidSampleScores>> {
        let n = self.cfg.rf.valid_sample_clips.min(self.valid_len());
        if n == 0 {
            return Ok(None);
        }
        let fail = |e: &dyn std::fmt::Display| TrainError::Other(format!("validation samples: {e}"));
        let cfg = &self.cfg;
        let frames = cfg.model.frames;
        VALID_SAMPLE_KEYFRAMES.check(frames).map_err(|e| fail(&e))?;
        let codec = MeshCodec::new(
            CodecVae::Frame(self.vae.clone()),
            self.store.p(),
            PadTo::BatchMax,
            device.clone(),
        )
        .map_err(|e| fail(&e))?;
        let text = TrainingText {
            tokenizer: Arc::clone(&self.tokenizer),
            model: model.text.clone(),
            max_len: cfg.text.max_len,
            dim: cfg.model.text_dim,
        };
        let models = LearnedModels::new(
            Arc::new(codec),
            model.mmdit.clone(),
            cfg.model.clone(),
            self.stats,
            Box::new(text),
        )
        .map_err(|e| fail(&e))?;
        let kind = match cfg.model.kf_mode {
            KfMode::InputMask => MethodKind::KeyframeRf,
            KfMode::ReplaceNoised | KfMode::None => MethodKind::ReplacementRf,
            KfMode::ImputeUntil => MethodKind::ImputeUntil {
                tau_star: cfg.rf.tau_star as f32,
                keyframes: KeyframeNoise::Clean,
            },
        };
        let mut options = SampleOptions::paper(cfg.model.kf_mode);
        options.n_grid = cfg.rf.valid_sample_grid;
        options.tau_star = cfg.rf.tau_star;
        let sampler = RfSampler::for_method(kind, Arc::new(models), options, 1.0).map_err(|e| fail(&e))?;
        let method = RfMethod::new(kind, sampler).map_err(|e| fail(&e))?;

        // Seeds of their own (u64::MAX is the validation loss's): fixed keyframes and sampler noise per clip.
        let seed = loop_common::step_seed(cfg.train.seed, u64::MAX - 1);
        let mut key_rng = ChaCha8Rng::seed_from_u64(seed);
        let mut sums = [0.0f64; 3];
        for (i, &store_index) in self.valid.store_indices[..n].iter().enumerate() {
            let clip = self.store.get(store_index).map_err(|e| fail(&e))?.clip;
            let keyframes: Vec<usize> = sample_keyframes(&VALID_SAMPLE_KEYFRAMES, frames, &mut key_rng)
                .iter()
                .enumerate()
                .filter_map(|(f, &k)| k.then_some(f))
                .collect();
            let clip_seed = seed.wrapping_add(i as u64);
            device.seed(clip_seed); // only `ReplaceNoise::Fresh` draws from the device
            let scored =
                complete_and_score(&method, &clip, &keyframes, &clip.caption, clip_seed).map_err(|e| fail(&e))?;
            let m = scored.metrics;
            for (s, v) in sums.iter_mut().zip([m.rmse, m.chamfer, m.dtw]) {
                *s += v / n as f64;
            }
        }
        Ok(Some(ValidSampleScores {
            clips: n,
            rmse: sums[0],
            chamfer: sums[1],
            dtw: sums[2],
        }))
    }

    /// At the validation after `step`: samples and logs when [`RfObjective::log_validation_samples`] is on and
    /// `step` is a multiple of `rf.valid_sample_every` or the last step.
    fn sample_at_validation(&self, model: &RfModel, device: &Device, step: u64) -> Result<()> {
        let Some(run) = &self.samples_run else {
            return Ok(());
        };
        let train = &self.cfg.train;
        let last = train.duration.steps(self.train_len(), train.batch_size);
        if !(step.is_multiple_of(self.cfg.rf.valid_sample_every) || step == last) {
            return Ok(());
        }
        let Some(s) = self.validation_samples(model, device)? else {
            return Ok(());
        };
        run.append_samples(step, &[s.rmse, s.chamfer, s.dtw])?;
        run.log(&format!(
            "step {step}: validation samples ({} clips, {}-point grid): rmse {:.4e}, chamfer {:.4e}, dtw {:.4e}",
            s.clips, self.cfg.rf.valid_sample_grid, s.rmse, s.chamfer, s.dtw
        ))
    }

    /// Number of VAL clips.
    pub fn valid_len(&self) -> usize {
        self.valid.store_indices.len()
    }

    /// Host bytes of the cached latents (0 with [`LatentCache::PerBatch`]).
    pub fn cached_bytes(&self) -> usize {
        [&self.train, &self.valid]
            .iter()
            .filter_map(|s| s.cached.as_ref())
            .map(LatentSet::bytes)
            .sum()
    }

    /// Builds the batch of positions `indices` of `subset`: z = μ + σξ or μ (`rf.latent`), standardized (SPEC
    /// §3.4), token-major; keyframe masks ([`draw_keyframe_mask`]); keyframe latents (Z itself, or the encoded
    /// noisy keyframes of §5.4 for `impute_until`); captions through the text model; keep_txt; ε; τ.
    /// Host draws (masks, keep_txt, keyframe noise) come from `rng`; ξ, ε and τ from the device stream.
    ///
    /// # Shapes
    /// - output batch: z0 `[B, P, C]`, z/z_key/eps `[B, P, T, C]`, mask `[B, T]`, text `[B, L, D_txt]`, keep_txt
    ///   and tau `[B]`
    pub fn batch(
        &self,
        model: &RfModel,
        subset: Subset,
        indices: &[usize],
        rng: &mut ChaCha8Rng,
        dropout: TextDropout,
        device: &Device,
    ) -> Result<RfStep> {
        let split = match subset {
            Subset::Train => &self.train,
            Subset::Valid => &self.valid,
        };
        let store_ids = indices
            .iter()
            .map(|&i| {
                split.store_indices.get(i).copied().ok_or_else(|| {
                    TrainError::Other(format!(
                        "{subset:?} index {i} out of range ({} clips)",
                        split.store_indices.len()
                    ))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let encoded;
        let (set, positions) = match &split.cached {
            Some(set) => (set, indices.to_vec()),
            None => {
                let inference = device.clone().without_autodiff();
                encoded = encode_latents(&self.vae, &self.store, &store_ids, store_ids.len(), &inference)?;
                (&encoded, (0..store_ids.len()).collect())
            }
        };
        let (b, t, p, c) = (indices.len(), set.frames, set.tokens, set.channels);
        let mut z0 = Vec::with_capacity(b * p * c);
        let mut mu = Vec::with_capacity(b * t * p * c);
        let mut logvar = Vec::with_capacity(b * t * p * c);
        let mut captions = Vec::with_capacity(b);
        for &i in &positions {
            let clip = &set.clips[i];
            z0.extend_from_slice(&clip.z0);
            mu.extend_from_slice(&clip.mu);
            logvar.extend_from_slice(&clip.logvar);
            captions.push(clip.caption.clone());
        }
        let z0: Tensor<3> = Tensor::from_data(TensorData::new(z0, [b, p, c]), device);
        let mu: Tensor<4> = Tensor::from_data(TensorData::new(mu, [b, t, p, c]), device);
        let z = match self.cfg.rf.latent {
            LatentDraw::Sample => {
                let logvar = Tensor::from_data(TensorData::new(logvar, [b, t, p, c]), device);
                frame_vae::sample(mu, logvar) // z = μ + σξ
            }
            LatentDraw::Mean => mu,
        };
        // SPEC §3.4: (z − mean)/std; VAE layout [B, T, P, C] → token-major [B, P, T, C].
        let z = self.stats.standardize_motion(z.swap_dims(1, 2));
        let z0 = self.stats.standardize_shape(z0);

        let kf_mode = self.cfg.model.kf_mode;
        let mask: Vec<bool> = (0..b)
            .flat_map(|_| draw_keyframe_mask(&self.cfg.rf, kf_mode, t, rng))
            .collect();
        let z_key = match kf_mode {
            KfMode::ImputeUntil => self.noisy_keyframe_latents(&store_ids, &mask, rng, device)?,
            KfMode::InputMask | KfMode::ReplaceNoised | KfMode::None => z.clone(),
        };
        let mask = Tensor::from_data(
            TensorData::new(mask.iter().map(|&m| f32::from(u8::from(m))).collect::<Vec<_>>(), [b, t]),
            device,
        );
        let keep: Vec<f32> = (0..b)
            .map(|_| match dropout {
                TextDropout::Apply => f32::from(u8::from(!rng.random_bool(self.cfg.rf.text_dropout))),
                TextDropout::Off => 1.0,
            })
            .collect();
        let text = model.encode_text(&self.tokenizer, &captions, self.cfg.text.max_len, device)?;
        let eps = Tensor::random([b, p, t, c], Distribution::Normal(0.0, 1.0), device);
        let tau = self.cfg.rf.tau_sampler.sample(b, device);
        Ok(RfStep {
            batch: RfBatch {
                z0,
                z,
                z_key,
                mask,
                text,
                keep_txt: Tensor::from_data(TensorData::new(keep, [b]), device),
            },
            eps,
            tau,
        })
    }

    /// SPEC §5.4 (SceneMI): keyframe vertices + i.i.d. N(0, (l · rf.keyframe_noise)²) with l ~ U(0, 1) per sample,
    /// first and last frames clean, real vertices only; encoded by the frozen VAE (posterior mean, SPEC §9.16) and
    /// standardized. Non-keyframe slots hold the clean frames' latents (unused: the mask hides them).
    ///
    /// # Shapes
    /// - mask: `B · T` row-major; output `[B, P, T, C]` on `device`
    fn noisy_keyframe_latents(
        &self,
        store_ids: &[usize],
        mask: &[bool],
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> Result<Tensor<4>> {
        let inference = device.clone().without_autodiff();
        let (mut clips, _) = load_clips(&self.store, store_ids, &inference)?;
        let [b, t, n, _] = clips.vertices.dims();
        let mut noise = vec![0.0f32; b * t * n * 3];
        for (bi, &n_real) in clips.n_real.iter().enumerate() {
            let std = rng.random::<f64>() * self.cfg.rf.keyframe_noise; // l · 0.02
            for f in 1..t.saturating_sub(1) {
                if !mask[bi * t + f] {
                    continue;
                }
                let row = &mut noise[(bi * t + f) * n * 3..][..n_real * 3];
                for x in row.iter_mut() {
                    *x = (standard_normal(rng) * std) as f32;
                }
            }
        }
        clips.vertices = clips.vertices + Tensor::from_data(TensorData::new(noise, [b, t, n, 3]), &inference);
        let enc = self.vae.vae_encode(&vae_batch(&clips, &inference)?);
        let z_key = self.stats.standardize_motion(enc.mu.swap_dims(1, 2));
        Ok(Tensor::from_data(z_key.into_data(), device))
    }
}

/// One N(0, 1) draw (Box–Muller).
fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]: ln is finite
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl Objective for RfObjective {
    type Model = RfModel;

    fn terms(&self) -> Vec<String> {
        RF_TERMS.iter().map(|s| s.to_string()).collect()
    }

    fn train_len(&self) -> usize {
        self.train.store_indices.len()
    }

    fn loss(&self, model: &RfModel, indices: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let step = self.batch(model, Subset::Train, indices, rng, TextDropout::Apply, device)?;
        let kf_frac = step.batch.mask.clone().mean();
        let rf = rf_training_loss(&model.mmdit, &step.batch, step.eps, step.tau, &self.cfg.loss_options()); // (R5)
        Ok(Losses {
            total: rf.clone(),
            terms: vec![rf, kf_frac],
        })
    }

    /// (R5) on the VAL split with a fixed seed (same masks, ξ, ε and τ at every validation) and no text dropout;
    /// then, when switched on, the validation samples of [`RfObjective::log_validation_samples`].
    fn validate(&self, model: &RfModel, device: &Device, step: u64) -> Result<Option<Vec<f64>>> {
        let n = self.valid_len();
        if n == 0 {
            return Ok(None);
        }
        let seed = loop_common::step_seed(self.cfg.train.seed, u64::MAX);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        device.seed(seed);
        let mut sums = [0.0f64; 3];
        let positions: Vec<usize> = (0..n).collect();
        for chunk in positions.chunks(self.cfg.train.micro_batch) {
            let step = self.batch(model, Subset::Valid, chunk, &mut rng, TextDropout::Off, device)?;
            let kf_frac = step.batch.mask.clone().mean();
            let rf = rf_training_loss(&model.mmdit, &step.batch, step.eps, step.tau, &self.cfg.loss_options());
            let w = chunk.len() as f64 / n as f64;
            let rf = loop_common::scalar(rf);
            for (s, v) in sums.iter_mut().zip([rf, loop_common::scalar(kf_frac), rf]) {
                *s += w * v;
            }
        }
        self.sample_at_validation(model, device, step)?;
        Ok(Some(sums.to_vec()))
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Runs

/// Options of `any4d train rf` besides the config.
pub struct RfRunOptions {
    /// Store folder (`--data`).
    pub data: PathBuf,
    /// The frozen VAE's run folder (`--vae`): required for a new run; for `--resume` it may be omitted (the run
    /// folder records it) and must otherwise name the same run.
    pub vae_run: Option<PathBuf>,
    /// Folder that holds run folders.
    pub runs_dir: PathBuf,
    /// Run name.
    pub name: String,
    /// Progress display.
    pub progress: ProgressMode,
    /// Ctrl-C flag.
    pub stop: StopFlag,
    /// Data-parallel devices (`--devices`, `--strategy`); `None` trains on `[device] backend`.
    pub parallel: Option<Parallel>,
}

/// The plain devices a run trains on: `opts.parallel`'s, or the one of `[device] backend`. Fails before a run
/// folder is claimed when a backend is not in this binary.
fn run_devices(cfg: &RfRunConfig, opts: &RfRunOptions) -> Result<Vec<Device>> {
    match &opts.parallel {
        Some(p) => p.plain_devices(cfg.device.precision),
        None => {
            backend::check(cfg.device.backend, cfg.device.precision)?;
            Ok(vec![backend::device(cfg.device.backend, cfg.device.precision)?])
        }
    }
}

fn open_store(data: &Path) -> Result<Store> {
    Store::open(data).map_err(|e| TrainError::Other(e.to_string()))
}

/// SPEC §4.1: the RF slots must match the VAE latents and the store windows.
fn check_compatible(cfg: &RfRunConfig, store: &Store, vae: &LoadedVae) -> Result<()> {
    vae.frame_vae()?;
    let c = vae.latent_channels();
    if cfg.model.channels != c {
        return Err(TrainError::Other(format!(
            "model.channels = {} but the VAE run {} has latent_channels = {c}: set model.channels = {c}",
            cfg.model.channels,
            vae.run.display()
        )));
    }
    if cfg.model.frames != store.frames() {
        return Err(TrainError::Other(format!(
            "model.frames = {} but the store {} holds {}-frame clips: set model.frames = {}",
            cfg.model.frames,
            store.dir().display(),
            store.frames(),
            store.frames()
        )));
    }
    Ok(())
}

/// Starts a new RF run with `cfg` on the frozen VAE of `opts.vae_run`; returns the run folder and the outcome.
/// The run folder gets `vae_run.json` (which VAE run and checkpoint step) and `tokenizer.json`.
pub fn train_rf(cfg: &RfRunConfig, opts: &RfRunOptions) -> Result<(RunFolder, Outcome)> {
    let vae_dir = opts
        .vae_run
        .as_deref()
        .ok_or_else(|| TrainError::Other("a new RF run needs the VAE run folder (--vae RUN)".into()))?;
    // Fail before claiming a run folder when the backend, the store or the VAE run is unusable.
    let devices = run_devices(cfg, opts)?;
    let store = open_store(&opts.data)?;
    let vae = runs::load_vae_run(vae_dir, &devices[0])?;
    check_compatible(cfg, &store, &vae)?;
    let captions = train_captions(&store)?;
    let tokenizer =
        ScratchTokenizer::train(&captions, cfg.text.vocab_size).map_err(|e| TrainError::Other(e.to_string()))?;

    let run = RunFolder::create(&opts.runs_dir, &opts.name, &cfg.to_toml()?, &RF_TERMS)?;
    runs::write_vae_record(&run, &VaeRunRecord::of(&vae)?)?;
    tokenizer
        .save(run.root())
        .map_err(|e| TrainError::Other(e.to_string()))?;
    run.log(&format!(
        "tokenizer trained on {} TRAIN captions: {} tokens",
        captions.len(),
        tokenizer.vocab_size()
    ))?;
    let outcome = run_rf(cfg, &run, opts, &vae, tokenizer, &devices, None)?;
    Ok((run, outcome))
}

/// Continues the RF run in `run_dir` from its newest checkpoint (config, tokenizer and VAE run from the run
/// folder; the backend may be overridden).
pub fn resume_rf(run_dir: &Path, backend: Option<backend::Backend>, opts: &RfRunOptions) -> Result<Outcome> {
    let run = RunFolder::open(run_dir)?;
    let mut cfg = RfRunConfig::parse(&run.config_text()?, &run.path(CONFIG_FILE))?;
    if let Some(b) = backend {
        cfg.device.backend = b;
    }
    let ckpt = crate::checkpoint::latest(&run.path(CHECKPOINTS_DIR))?.ok_or_else(|| TrainError::Checkpoint {
        path: run_dir.to_path_buf(),
        reason: "no complete checkpoint to resume".into(),
    })?;
    let record = runs::read_vae_record(run_dir)?;
    if let Some(given) = &opts.vae_run {
        let given = std::fs::canonicalize(given).map_err(io_err("resolve VAE run folder", given))?;
        if given != record.run {
            return Err(TrainError::Other(format!(
                "--vae {} differs from the VAE run {} that {} was trained on",
                given.display(),
                record.run.display(),
                run_dir.display()
            )));
        }
    }
    let devices = run_devices(&cfg, opts)?;
    let vae = record.load(&devices[0])?;
    let tokenizer = ScratchTokenizer::load(run_dir).map_err(|e| TrainError::Other(e.to_string()))?;
    run_rf(&cfg, &run, opts, &vae, tokenizer, &devices, Some(ckpt))
}

fn train_captions(store: &Store) -> Result<Vec<String>> {
    store
        .indices(Split::Train)
        .into_iter()
        .map(|i| {
            store
                .get(i)
                .map(|c| c.clip.caption)
                .map_err(|e| TrainError::Other(e.to_string()))
        })
        .collect()
}

fn run_rf(
    cfg: &RfRunConfig,
    run: &RunFolder,
    opts: &RfRunOptions,
    vae: &LoadedVae,
    tokenizer: ScratchTokenizer,
    devices: &[Device],
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    let vocab = tokenizer.vocab_size();
    let mut objective = RfObjective::new(cfg, &opts.data, vae, tokenizer, &devices[0])?;
    objective.log_validation_samples(run)?;
    run.log(&format!(
        "RF {:?} on {} ({} train / {} val clips, latents {:?}: {:.1} MiB), VAE {} step {}, backend {}",
        cfg.model.kf_mode,
        opts.data.display(),
        objective.train_len(),
        objective.valid_len(),
        cfg.rf.latent_cache,
        objective.cached_bytes() as f64 / (1024.0 * 1024.0),
        vae.run.display(),
        vae.step,
        cfg.device.backend
    ))?;
    let ad: Vec<Device> = devices.iter().map(|d| d.clone().autodiff()).collect();
    ad[0].seed(cfg.train.seed);
    let model = cfg.model_config(vocab).init(&ad[0]);
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: ad[0].clone(),
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
    };
    let (_, outcome) = match &opts.parallel {
        Some(p) => {
            run.log(&format!("data-parallel over {} devices ({:?})", ad.len(), p.strategy))?;
            train_data_parallel(&objective, model, setup, &ad, p.strategy)?
        }
        None => loop_common::train(&objective, model, setup)?,
    };
    Ok(outcome)
}
