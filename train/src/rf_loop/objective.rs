//! The RF objective (R5) with its batches, CFG text dropout and validation sampling.

use std::path::Path;
use std::sync::Arc;

use any4d_data::batch::PadTo;
use any4d_data::keyframes::sample_keyframes;
use any4d_data::store::{Split, Store};
use any4d_eval::learned::{LearnedModels, MeshCodec, MeshVae as CodecVae, RfSampler};
use any4d_eval::methods::{KeyframeNoise, MethodKind, RfMethod, complete_and_score};
use any4d_model::frame_vae::{self, FrameVae};
use any4d_model::latent_stats::LatentStats;
use any4d_model::mmdit::KfMode;
use any4d_model::rectified_flow::{RfBatch, SampleOptions, rf_training_loss};
use any4d_model::text::scratch::{ScratchTextModel, ScratchTokenizer};
use any4d_model::text::{TextBatch, TextEncoder, TextError};
use burn::prelude::{Device, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Result, TrainError};
use crate::loop_common::{self, Losses, Objective};
use crate::run_folder::{RunFolder, SAMPLES_FILE};
use crate::runs::LoadedVae;
use crate::vae_loop::{MeshVae, load_clips, vae_batch};

use super::config::{LatentCache, LatentDraw, RfRunConfig};
use super::latents::{LatentSet, encode_latents};
use super::network::{RfModel, draw_keyframe_mask};
use super::{RF_TERMS, SAMPLE_TERMS, VALID_SAMPLE_KEYFRAMES};

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

/// Mean scores of one validation-sampling round (docs/method.md §6 (E1)–(E3), normalised frame of each clip's frame 0).
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
    /// [`RfSampler`] on an `rf.valid_sample_grid`-point midpoint grid with CFG weight 1 (docs/method.md §4.6: (R3) for
    /// `input_mask`, the replacement sampler (R7)–(R8) for `replace_noised` and `none`, (R9) with `rf.tau_star`
    /// for `impute_until`), keyframes replaced by the ground truth, then (E1)–(E3) of docs/method.md §6 against the
    /// clip. Every draw is seeded from `train.seed`, so the same network gives the same scores; the training RNG
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

    /// Builds the batch of positions `indices` of `subset`: z = μ + σξ or μ (`rf.latent`), standardized (docs/method.md
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
        // docs/method.md §3.4: (z − mean)/std; VAE layout [B, T, P, C] → token-major [B, P, T, C].
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

    /// docs/method.md §5.4 (SceneMI): keyframe vertices + i.i.d. N(0, (l · rf.keyframe_noise)²) with l ~ U(0, 1) per
    /// sample, first and last frames clean, real vertices only; encoded by the frozen VAE (posterior mean,
    /// docs/method.md §9 item 16) and standardized. Non-keyframe slots hold the clean frames' latents (unused: the mask
    /// hides them).
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

pub(super) fn open_store(data: &Path) -> Result<Store> {
    Store::open(data).map_err(|e| TrainError::Other(e.to_string()))
}

/// docs/method.md §4.1: the RF slots must match the VAE latents and the store windows.
pub(super) fn check_compatible(cfg: &RfRunConfig, store: &Store, vae: &LoadedVae) -> Result<()> {
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
