//! The batches of the RF objective (docs/method.md §4.5, §5.4): frozen-VAE latents of a split (cached or encoded
//! per batch), a posterior draw standardised by the VAE's statistics (§3.4), keyframe masks, keyframe latents (clean,
//! or SceneMI's noisy keyframes for `impute_until`), captions through the text model, CFG dropout, ε and τ.

use std::path::Path;
use std::sync::Arc;

use any4d_data::keyframes::sample_keyframes;
use any4d_data::scene::features::GridSpec;
use any4d_data::store::{Split, Store};
use any4d_model::anchor::keyframe_lerp;
use any4d_model::any_vae::AnyMeshVae;
use any4d_model::latent_stats::LatentStats;
use any4d_model::mesh_vae::{self, MeshVae};
use any4d_model::mmdit::{KeyframeConditioning, SceneInput};
use any4d_model::noise::{self, standard_normal};
use any4d_model::rectified_flow::RfBatch;
use any4d_model::text::caption_keep;
use any4d_model::text::scratch::ScratchTokenizer;
use burn::prelude::{Device, Tensor, TensorData};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::error::{Result, TrainError};
use crate::runs::LoadedVae;
use crate::vae_loop::{load_clips, vae_batch};

use super::config::{LatentCache, LatentDraw, RfRunConfig, RfSection};
use super::latent_files::{DiskLatents, Encoder, FileState};
use super::latents::{LatentSet, encode_augmented, encode_latents_on_workers};
use super::network::RfModel;

/// Whether a batch applies the CFG caption dropout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextDropout {
    /// keep_txt ~ Bernoulli(1 − rf.text_dropout) (training); always 0 for a caption with no text.
    Apply,
    /// keep_txt = 1 (validation); 0 for a caption with no text.
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

/// Builds RF batches of one store on a frozen VAE: the data half of the RF objective.
pub struct RfBatcher {
    cfg: RfRunConfig,
    stats: LatentStats,
    tokenizer: Arc<ScratchTokenizer>,
    vae: AnyMeshVae,
    /// FPS tokens P of the VAE run (`vae.tokens`).
    tokens: usize,
    /// The grid of (S1) when the network reads the scene (docs/method.md §4.12).
    scene_grid: Option<GridSpec>,
    store: Store,
    train: SplitLatents,
    valid: SplitLatents,
    /// With [`LatentCache::Disk`]: the latent files of every shard, and what preparing them did.
    disk: Option<(DiskLatents, String)>,
}

/// The keyframe mask m of one training window of `frames` frames (true = observed keyframe), drawn with
/// `rf.kf_sampler` (docs/method.md §4.5, §5.4). Modes trained without keyframes (`replace_noised`, `none`) get
/// all-false masks and consume no random numbers.
pub fn training_mask(
    rf: &RfSection,
    conditioning: KeyframeConditioning,
    frames: usize,
    rng: &mut impl Rng,
) -> Vec<bool> {
    if !conditioning.has_mask_channels() {
        return vec![false; frames];
    }
    sample_keyframes(&rf.kf_sampler.strategy(rf.k_max), frames, rng)
}

impl RfBatcher {
    /// Checks that the RF config fits the VAE and the store in `data`; with [`LatentCache::Memory`] encodes the
    /// TRAIN and VAL clips once with the frozen VAE (on the inference `device`); with [`LatentCache::Disk`] makes the
    /// latent files of every shard in `latents` current (encoding those missing or stale) and opens them.
    pub fn new(
        cfg: &RfRunConfig,
        data: &Path,
        latents: Option<&Path>,
        vae: &LoadedVae,
        tokenizer: ScratchTokenizer,
        device: &Device,
    ) -> Result<Self> {
        let store = open_store(data)?;
        check_compatible(cfg, &store, vae)?;
        let frozen = vae.model.clone();
        let workers = cfg.device.backend.encoding_workers();
        let scene_grid = cfg.model.scene.any().then(|| cfg.model.scene.grid_spec());
        let split = |split: Split| -> Result<SplitLatents> {
            let store_indices = store.indices(split);
            let cached = match cfg.rf.latent_cache {
                LatentCache::Memory => Some(encode_latents_on_workers(
                    &frozen,
                    &store,
                    &store_indices,
                    cfg.train.micro_batch,
                    vae.tokens(),
                    device,
                    workers,
                    scene_grid.as_ref(),
                )?),
                LatentCache::PerBatch | LatentCache::Disk => None,
            };
            Ok(SplitLatents { store_indices, cached })
        };
        let (train, valid) = (split(Split::Train)?, split(Split::Val)?);
        let disk = match cfg.rf.latent_cache {
            LatentCache::Disk => {
                let dir = latents.ok_or_else(|| {
                    TrainError::Setup("rf.latent_cache = \"disk\" needs a folder for the latent files".into())
                })?;
                let encoder = Encoder::new(vae, cfg.train.micro_batch, workers, device)?;
                let (mut reused, mut encoded) = (0, 0);
                let disk = DiskLatents::prepare(dir, &store, &encoder, &mut |_, state| match state {
                    FileState::Current => reused += 1,
                    FileState::Missing | FileState::Stale(_) => encoded += 1,
                })?;
                let note = format!(
                    "latent files in {}: {reused} shard(s) reused, {encoded} encoded",
                    dir.display()
                );
                Some((disk, note))
            }
            LatentCache::Memory | LatentCache::PerBatch => None,
        };
        Ok(RfBatcher {
            cfg: cfg.clone(),
            stats: vae.stats,
            tokenizer: Arc::new(tokenizer),
            vae: frozen,
            tokens: vae.tokens(),
            scene_grid,
            store,
            train,
            valid,
            disk,
        })
    }

    /// What preparing the latent files did ([`LatentCache::Disk`]); `None` otherwise.
    pub fn latent_files_note(&self) -> Option<&str> {
        self.disk.as_ref().map(|(_, note)| note.as_str())
    }

    /// Number of TRAIN clips (stored windows).
    pub fn train_len(&self) -> usize {
        self.train.store_indices.len()
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

    /// The run config.
    pub fn config(&self) -> &RfRunConfig {
        &self.cfg
    }

    /// The store the clips come from.
    pub fn store(&self) -> &Store {
        &self.store
    }

    /// Store indices of the TRAIN clips (windows), in store order.
    pub fn train_indices(&self) -> &[usize] {
        &self.train.store_indices
    }

    /// Store indices of the VAL clips, in store order.
    pub fn valid_indices(&self) -> &[usize] {
        &self.valid.store_indices
    }

    /// The frozen VAE (frame-wise; sequence-wise for the AnimateAnyMesh reference).
    pub fn vae(&self) -> &AnyMeshVae {
        &self.vae
    }

    /// FPS tokens P the VAE encodes.
    pub fn tokens(&self) -> usize {
        self.tokens
    }

    /// The VAE's latent statistics.
    pub fn stats(&self) -> LatentStats {
        self.stats
    }

    /// The caption tokenizer (shared).
    pub fn tokenizer(&self) -> &Arc<ScratchTokenizer> {
        &self.tokenizer
    }

    /// The root mean square of Z − A over the generated slots of the first `clips` TRAIN windows (docs/method.md
    /// §4.10: the size the anchor's scale s should have), on standardized posterior means with training keyframe masks
    /// from `rng`; `None` without cached latents (in memory or on disk) or TRAIN clips; an error when the latent
    /// files cannot be read.
    pub fn anchor_residual_rms(&self, clips: usize, rng: &mut ChaCha8Rng, device: &Device) -> Result<Option<f64>> {
        let read;
        let set = match (&self.train.cached, &self.disk) {
            (Some(set), _) => set,
            (None, Some((disk, _))) => {
                let ids = &self.train.store_indices[..clips.min(self.train.store_indices.len())];
                read = disk.read(&self.store, ids)?;
                &read
            }
            (None, None) => return Ok(None),
        };
        let n = clips.min(set.clips.len());
        if n == 0 {
            return Ok(None);
        }
        let (t, p, c) = (set.frames, set.tokens, set.channels);
        let mu: Vec<f32> = set.clips[..n].iter().flat_map(|clip| clip.mu.iter().copied()).collect();
        let z = self
            .stats
            .standardize_motion(Tensor::<4>::from_data(TensorData::new(mu, [n, t, p, c]), device).swap_dims(1, 2));
        let mask: Vec<f32> = (0..n)
            .flat_map(|_| training_mask(&self.cfg.rf, self.cfg.model.conditioning, t, rng))
            .map(|m| f32::from(u8::from(m)))
            .collect();
        let generated = mask.iter().filter(|&&m| m == 0.0).count() * p * c;
        let mask = Tensor::<2>::from_data(TensorData::new(mask, [n, t]), device);
        let residual = z.clone() - keyframe_lerp(z, mask.clone());
        let free = mask.neg().add_scalar(1.0).reshape([n, 1, t, 1]);
        let sum = f64::from((residual.powi_scalar(2) * free).sum().into_scalar::<f32>());
        Ok((generated > 0).then(|| (sum / generated as f64).sqrt()))
    }

    /// Builds the batch of positions `indices` of `subset`: z = μ + σξ or μ (`rf.latent`), standardized (docs/method.md
    /// §3.4), token-major; keyframe masks ([`training_mask`]); keyframe latents (Z itself, or the encoded
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
                    TrainError::Loop(format!(
                        "{subset:?} index {i} out of range ({} clips)",
                        split.store_indices.len()
                    ))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let encoded;
        let (set, positions) = match (&split.cached, &self.disk) {
            (Some(set), _) => (set, indices.to_vec()),
            (None, Some((disk, _))) => {
                encoded = disk.read(&self.store, &store_ids)?;
                (&encoded, (0..store_ids.len()).collect())
            }
            (None, None) => {
                let inference = device.clone().without_autodiff();
                // Training examples are augmented (docs/method.md §2.9) with draws from the micro-batch's generator.
                let augment = &self.cfg.rf.augment;
                let augment = (subset == Subset::Train && !augment.is_off()).then_some((augment, &mut *rng));
                encoded = encode_augmented(
                    &self.vae,
                    &self.store,
                    &store_ids,
                    store_ids.len(),
                    self.tokens,
                    augment,
                    self.scene_grid.as_ref(),
                    &inference,
                )?;
                (&encoded, (0..store_ids.len()).collect())
            }
        };
        let (b, t, p, c) = (indices.len(), set.frames, set.tokens, set.channels);
        let mut z0 = Vec::with_capacity(b * p * c);
        let mut mu = Vec::with_capacity(b * t * p * c);
        let mut logvar = Vec::with_capacity(b * t * p * c);
        let mut captions = Vec::with_capacity(b);
        let mut scenes = Vec::with_capacity(b);
        for &i in &positions {
            let clip = &set.clips[i];
            z0.extend_from_slice(&clip.z0);
            mu.extend_from_slice(&clip.mu);
            logvar.extend_from_slice(&clip.logvar);
            captions.push(clip.caption.clone());
            scenes.push(clip.scene.as_ref());
        }
        let z0: Tensor<3> = Tensor::from_data(TensorData::new(z0, [b, p, c]), device);
        let mu: Tensor<4> = Tensor::from_data(TensorData::new(mu, [b, t, p, c]), device);
        let z = match self.cfg.rf.latent {
            LatentDraw::Sample => {
                let logvar = Tensor::from_data(TensorData::new(logvar, [b, t, p, c]), device);
                mesh_vae::sample_with(mu, logvar, rng) // z = μ + σξ
            }
            LatentDraw::Mean => mu,
        };
        // docs/method.md §3.4: (z − mean)/std; VAE layout [B, T, P, C] → token-major [B, P, T, C].
        let z = self.stats.standardize_motion(z.swap_dims(1, 2));
        let z0 = self.stats.standardize_shape(z0);

        let conditioning = self.cfg.model.conditioning;
        let mask: Vec<bool> = (0..b)
            .flat_map(|_| training_mask(&self.cfg.rf, conditioning, t, rng))
            .collect();
        let z_key = match conditioning {
            KeyframeConditioning::ImputeUntil => self.noisy_keyframe_latents(&store_ids, &mask, rng, device)?,
            KeyframeConditioning::InputMask | KeyframeConditioning::ReplaceNoised | KeyframeConditioning::None => {
                z.clone()
            }
        };
        let mask = Tensor::from_data(
            TensorData::new(mask.iter().map(|&m| f32::from(u8::from(m))).collect::<Vec<_>>(), [b, t]),
            device,
        );
        let scene =
            self.cfg.model.scene.any().then(|| {
                SceneInput::from_features(&scenes, self.cfg.model.scene.grid_cells(), t, p, mask.clone(), device)
            });
        // A caption with no text is always the unconditional input (caption_keep), whatever the dropout draw.
        let keep: Vec<f32> = caption_keep(&captions)
            .into_iter()
            .map(|has_text| match dropout {
                TextDropout::Apply => has_text * f32::from(u8::from(!rng.random_bool(self.cfg.rf.text_dropout))),
                TextDropout::Off => has_text,
            })
            .collect();
        let text = model.encode_text(&self.tokenizer, &captions, self.cfg.text.max_len, device)?;
        let eps = noise::normal([b, p, t, c], rng, device);
        let tau = self.cfg.rf.tau_sampler.sample_with(b, rng, device);
        Ok(RfStep {
            batch: RfBatch {
                z0,
                z,
                z_key,
                mask,
                text,
                keep_txt: Tensor::from_data(TensorData::new(keep, [b]), device),
                scene,
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
        let enc = self.vae.encode_vae_batch(&vae_batch(&clips, self.tokens, &inference)?);
        let z_key = self.stats.standardize_motion(enc.mu.swap_dims(1, 2));
        Ok(Tensor::from_data(z_key.into_data(), device))
    }
}

pub(super) fn open_store(data: &Path) -> Result<Store> {
    Ok(Store::open(data)?)
}

/// docs/method.md §4.1: the RF slots must match the VAE latents and the store windows; on a sequence-wise VAE
/// (the AnimateAnyMesh reference, §5.5) the RF has one trajectory slot and no keyframes.
pub(super) fn check_compatible(cfg: &RfRunConfig, store: &Store, vae: &LoadedVae) -> Result<()> {
    vae.check_store_any_kind(store)?;
    check_slots(cfg, store, vae)?;
    let c = vae.latent_channels();
    if cfg.model.channels != c {
        return Err(TrainError::Setup(format!(
            "model.channels = {} but the VAE run {} has latent_channels = {c}: set model.channels = {c}",
            cfg.model.channels,
            vae.run.display()
        )));
    }
    // Refused before the first batch is built: a micro-batch whose activations cannot fit this machine.
    let estimate = cfg
        .model
        .activation_bytes(cfg.train.micro_batch, vae.tokens(), cfg.text.max_len);
    let host = match cfg.device.backend {
        crate::backend::Backend::Flex | crate::backend::Backend::Ndarray => any4d_model::summary::host_memory_bytes(),
        _ => None,
    };
    let what = format!(
        "a micro-batch of {} clips × ({} tokens + {} caption tokens) at model.width {} × {} blocks",
        cfg.train.micro_batch,
        vae.tokens(),
        cfg.text.max_len,
        cfg.model.width,
        cfg.model.blocks
    );
    any4d_model::summary::check_activation_estimate(
        &what,
        estimate,
        host.unwrap_or(crate::backend::MAX_ACTIVATION_BYTES),
    )
    .map_err(TrainError::Setup)
}

/// The RF's latent slots against the VAE kind and the store: T frames on a frame-wise VAE; one trajectory slot and
/// no keyframes on a sequence-wise VAE (the AnimateAnyMesh reference), whose validation samples need windows of 3
/// frames or more.
fn check_slots(cfg: &RfRunConfig, store: &Store, vae: &LoadedVae) -> Result<()> {
    let aam_config = cfg.model.frames == 1 && cfg.model.conditioning == KeyframeConditioning::None;
    if vae.model.clip_frames().is_some() {
        if cfg.model.scene.any() {
            return Err(TrainError::Setup(format!(
                "the VAE run {} is sequence-wise (the AnimateAnyMesh reference, one trajectory latent per clip): its \
                 tokens have no frames for the scene's keyframe offsets or grid to join; set model.scene.global and \
                 model.scene.local to false",
                vae.run.display()
            )));
        }
        if !aam_config {
            return Err(TrainError::Setup(format!(
                "the VAE run {} is sequence-wise (one trajectory latent per clip): an RF on it is the AnimateAnyMesh \
                 reference and needs model.frames = 1 and model.conditioning = \"none\" (configs/rf/aam_*.toml), got \
                 {} and {:?}",
                vae.run.display(),
                cfg.model.frames,
                cfg.model.conditioning
            )));
        }
        if cfg.rf.valid_sample_every > 0 {
            super::VALID_SAMPLE_KEYFRAMES.check(store.frames()).map_err(|e| {
                TrainError::Setup(format!(
                    "rf.valid_sample_every > 0 needs windows of at least 3 frames, the store {} holds {}: {e}",
                    store.dir().display(),
                    store.frames()
                ))
            })?;
        }
        return Ok(());
    }
    if aam_config && store.frames() > 1 {
        return Err(TrainError::Setup(format!(
            "model.frames = 1 with model.conditioning = \"none\" is the AnimateAnyMesh reference, which needs a \
             sequence-wise VAE run (configs/vae/dymesh_*.toml); {} is frame-wise",
            vae.run.display()
        )));
    }
    if cfg.model.frames != store.frames() {
        return Err(TrainError::Setup(format!(
            "model.frames = {} but the store {} holds {}-frame clips: set model.frames = {}",
            cfg.model.frames,
            store.dir().display(),
            store.frames(),
            store.frames()
        )));
    }
    Ok(())
}
