//! The RF methods' window sampler: ours, the replacement Baseline, impute-until-τ* and the AnimateAnyMesh reference
//! (docs/method.md §4.6, §5.1, §5.4, §5.5).

use std::sync::Arc;

use any4d_data::Clip;
use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};
use any4d_data::scene::features::clip_scene_features;
use any4d_model::mmdit::{KeyframeConditioning, SceneInput, replace_keyframes};
use any4d_model::rectified_flow::{Conditioning, ReplaceNoise, SampleOptions, sample_mmdit};
use any4d_model::text::caption_keep;
use burn::prelude::*;
use burn::tensor::TensorData;

use crate::methods::{MethodKind, Request, WindowSampler};

use crate::error::{EvalError, Result};

use super::*;

/// Sampled latents of one window (see [`RfSampler::sample_latents`]).
#[derive(Debug, Clone)]
pub struct SampledWindow {
    /// Encoding of frame 0 and the keyframes (E₀, x̄₀, z₀ for decoding).
    pub encoding: WindowEncoding,
    /// Raw keyframe latents μ at the keyframe frames, zero elsewhere, `[1, S, P, C]` with S = the network's slots
    /// (T; 1 for the AnimateAnyMesh reference, which has no keyframes: zero).
    pub keyframe_latents: Tensor<4>,
    /// Keyframe mask m, `[S]`, 1 = keyframe.
    pub mask: Vec<f32>,
    /// De-standardized sampled latents, `[1, S, P, C]` (the VAE's layout).
    pub latents: Tensor<4>,
}

/// An RF method's window sampler (docs/method.md §4.6): keyframe latents = posterior mean μ, standardized; ε from the
/// seed; [`sample_mmdit`] with the mode's input rule ((R3) ours, (R7)–(R8) baseline, (R9) impute-until-τ*, none for
/// the AnimateAnyMesh reference of §5.5 on the sequence-wise VAE); de-standardize; decode every frame with E₀ of the
/// reference.
pub struct RfSampler {
    models: Arc<LearnedModels>,
    options: SampleOptions,
    guidance: f64,
}

impl RfSampler {
    /// `options.conditioning` must match the network's input layout (mask channels or not); `guidance` is the CFG
    /// weight w (1.0 in the paper: one conditional branch). ε comes from the seed ([`sampler_noise`]); only
    /// `ReplaceNoise::Fresh` draws from a host stream that each batch seeds from its requests' seeds.
    pub fn new(models: Arc<LearnedModels>, options: SampleOptions, guidance: f64) -> Result<Self> {
        let bad = |field: &str, reason: String| Err(EvalError::invalid("rf sampler", field, reason));
        let net = models.rf_config.conditioning;
        if options.conditioning.has_mask_channels() != net.has_mask_channels() {
            return bad(
                "conditioning",
                format!(
                    "sampling with {:?} needs a network {} mask channels, but it was built for {net:?}",
                    options.conditioning,
                    if options.conditioning.has_mask_channels() {
                        "with"
                    } else {
                        "without"
                    }
                ),
            );
        }
        if options.n_grid < 2 {
            return bad(
                "n_grid",
                format!("needs at least 2 grid points, got {}", options.n_grid),
            );
        }
        if !(0.0..=1.0).contains(&options.tau_star) {
            return bad("tau_star", format!("{} is outside [0, 1]", options.tau_star));
        }
        if !guidance.is_finite() {
            return bad("guidance", format!("{guidance} is not finite"));
        }
        if !(options.noise_scale.is_finite() && options.noise_scale >= 0.0) {
            return bad(
                "noise_scale",
                format!("{} is not a finite scale ≥ 0", options.noise_scale),
            );
        }
        Ok(Self {
            models,
            options,
            guidance,
        })
    }

    /// The sampler of an RF method kind: `KeyframeRf` → (R3), `ReplacementRf` → (R7)–(R8), `ImputeUntil` → (R9)
    /// with its τ*; solver, grid and replacement noise from `base`.
    pub fn for_method(
        kind: MethodKind,
        models: Arc<LearnedModels>,
        base: SampleOptions,
        guidance: f64,
    ) -> Result<Self> {
        let (conditioning, tau_star) = match kind {
            MethodKind::KeyframeRf => (KeyframeConditioning::InputMask, base.tau_star),
            MethodKind::ReplacementRf => (KeyframeConditioning::ReplaceNoised, base.tau_star),
            MethodKind::ImputeUntil { tau_star, .. } => (KeyframeConditioning::ImputeUntil, f64::from(tau_star)),
            MethodKind::Aam => (KeyframeConditioning::None, base.tau_star),
            other => {
                return Err(EvalError::invalid(
                    "rf sampler",
                    other.label(),
                    "is not a rectified-flow method",
                ));
            }
        };
        let sequencewise = models.codec.vae().clip_frames().is_some();
        if sequencewise && models.rf_config.scene.any() {
            return Err(EvalError::invalid(
                "rf sampler",
                "model.scene",
                "an RF on a sequence-wise VAE has no frames for the scene's features to join",
            ));
        }
        if (kind == MethodKind::Aam) != sequencewise {
            let reason = if sequencewise {
                "needs an RF trained on a frame-wise VAE; this one is the AnimateAnyMesh reference (an RF on the \
                 sequence-wise VAE that takes no keyframes): it runs only as method `aam` of `eval run`"
            } else {
                "needs the AnimateAnyMesh reference, an RF trained on a sequence-wise VAE (configs/rf/aam_*.toml); \
                 this RF was trained on a frame-wise VAE"
            };
            return Err(EvalError::invalid("rf sampler", kind.label(), reason));
        }
        let options = SampleOptions {
            conditioning,
            tau_star,
            ..base
        };
        Self::new(models, options, guidance)
    }

    /// The sampler settings.
    pub fn options(&self) -> &SampleOptions {
        &self.options
    }

    /// What a scene-aware network is told of the requests' scenes (docs/method.md §4.12): (S1) around each window's
    /// frame 0 and (S2) of the anchors its encoding used, at the keyframes of `mask` (none for a network trained
    /// without keyframes, as in its training); `None` for a network without scene parts.
    ///
    /// # Shapes
    /// - mask: `[B, T]` (1 = keyframe)
    fn scene_input(
        &self,
        requests: &[Request<'_>],
        windows: &[(WindowEncoding, Tensor<4>, Vec<f32>)],
        mask: Tensor<2>,
    ) -> Result<Option<SceneInput>> {
        let m = &self.models;
        let scene = &m.rf_config.scene;
        if !scene.any() {
            return Ok(None);
        }
        let spec = scene.grid_spec();
        let features = requests
            .iter()
            .zip(windows)
            .map(|(r, (encoding, _, _))| {
                r.scene
                    .map(|s| clip_scene_features(r.clip, s, &encoding.anchors, &spec))
                    .transpose()
                    .map_err(EvalError::from)
            })
            .collect::<Result<Vec<_>>>()?;
        let refs: Vec<_> = features.iter().map(Option::as_ref).collect();
        let [b, t] = mask.dims();
        let mask = if self.options.conditioning.has_mask_channels() {
            mask
        } else {
            mask.zeros_like()
        };
        let tokens = windows.first().map_or(0, |(e, _, _)| e.anchors.len());
        let device = m.codec.device().clone();
        debug_assert_eq!(b, refs.len());
        Ok(Some(SceneInput::from_features(
            &refs,
            scene.grid_cells(),
            t,
            tokens,
            mask,
            &device,
        )))
    }

    /// Samples the trajectory latents of one window. Only frame 0 and the `keyframes` of `clip` are read.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N_v]` rows; `latents` `[1, T, P, C]`.
    pub fn sample_latents(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<SampledWindow> {
        let mut out = self.sample_latents_batch(&[Request::new(clip, keyframes, seed)], caption)?;
        Ok(out.remove(0))
    }

    /// [`RfSampler::sample_latents`] for several windows with one caption: every ODE evaluation is one network
    /// call over the whole batch. Each window keeps its own ε (from its seed), keyframes and encoding, so the
    /// result per window is the one [`RfSampler::sample_latents`] gives.
    pub fn sample_latents_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<SampledWindow>> {
        let m = &self.models;
        let cfg = &m.rf_config;
        let device = m.codec.device().clone();
        // Latent slots of the network: T frames, or the one trajectory slot of the sequence-wise VAE.
        let t = cfg.frames;
        let sequencewise = m.codec.vae().clip_frames();
        let window = sequencewise.unwrap_or(t);
        let mut windows = Vec::with_capacity(requests.len());
        for r in requests {
            let clip = r.clip;
            if clip.frames != window {
                return Err(EvalError::invalid(
                    &clip.id,
                    "frames",
                    match sequencewise {
                        Some(_) => format!(
                            "the window has {} frames, the sequence-wise VAE encodes windows of T = {window}",
                            clip.frames
                        ),
                        None => format!(
                            "the window has {} frames, the RF was built for T = {window}",
                            clip.frames
                        ),
                    },
                ));
            }
            let keys = keyframe_list(clip, r.keyframes)?;
            let encoding = match sequencewise {
                // docs/method.md §5.5: the reference mesh and the caption only; no keyframe latent, no mask.
                Some(_) => m.codec.encode_reference(clip)?,
                None => m.codec.encode(clip, &encoded_frames(&keys))?,
            };
            let c = encoding.z0.dims()[2];
            if c != cfg.channels {
                return Err(EvalError::invalid(
                    &clip.id,
                    "latents",
                    format!(
                        "the VAE gives C = {c} channels, the RF was built for C = {}",
                        cfg.channels
                    ),
                ));
            }
            let (keyframe_latents, mask) = match sequencewise {
                Some(_) => (Tensor::zeros([1, 1, encoding.z0.dims()[1], c], &device), vec![0.0]),
                None => scatter_keyframes(&encoding, &keys, &device)?,
            };
            windows.push((encoding, keyframe_latents, mask));
        }
        let Some((first, _, _)) = windows.first() else {
            return Ok(Vec::new());
        };
        let [_, p, c] = first.z0.dims();
        let b = windows.len();
        let masks: Vec<f32> = windows.iter().flat_map(|(_, _, m)| m.iter().copied()).collect();
        let mask_t: Tensor<2> = Tensor::from_data(TensorData::new(masks, [b, t]), &device);
        let keyframe_latents = Tensor::cat(windows.iter().map(|(_, k, _)| k.clone()).collect(), 0); // [B, T, P, C], raw μ
        let z0 = Tensor::cat(windows.iter().map(|(e, _, _)| e.z0.clone()).collect(), 0); // [B, P, C]
        let cond = Conditioning {
            z0: m.stats.standardize_shape(z0),
            z_key: m.stats.standardize_motion(keyframe_latents.clone()).swap_dims(1, 2), // [B, P, T, C]
            mask: mask_t.clone(),
            scene: self.scene_input(requests, &windows, mask_t.clone())?,
        };
        let text = m
            .text
            .encode(&[caption.to_string()], &device)
            .map_err(|e| EvalError::invalid(&first.id, "caption", e.to_string()))?
            .states;
        let [_, l, d] = text.dims();
        let text = text.expand([b, l, d]);
        let keep =
            Tensor::<1>::from_data(TensorData::new(caption_keep(&[caption.to_string()]), [1]), &device).expand([b]);
        let eps = Tensor::cat(
            requests
                .iter()
                .map(|r| sampler_noise(r.seed, [1, p, t, c], &device))
                .collect(),
            0,
        );
        let mut options = self.options;
        if options.replace_noise == ReplaceNoise::Fresh {
            // Fresh replacement noise is drawn from a host stream seeded by the requests: the same requests in the
            // same batches give the same samples, whatever other threads draw.
            options.fresh_seed = requests.iter().fold(0x5EED_F2E5_u64, |h, r| {
                splitmix64(h ^ r.seed.wrapping_mul(GOLDEN_GAMMA))
            });
        }
        let x1 = sample_mmdit(&m.rf, &cond, text, keep, eps, self.guidance, &options); // (R6)
        let mut latents = m.stats.destandardize_motion(x1); // [B, P, T, C]
        if matches!(
            self.options.conditioning,
            KeyframeConditioning::InputMask | KeyframeConditioning::ReplaceNoised
        ) {
            // docs/method.md §4.6: keyframe slots are Z_key; done on raw latents so they are μ exactly.
            latents = replace_keyframes(latents, keyframe_latents.swap_dims(1, 2), mask_t);
        }
        let latents = latents.swap_dims(1, 2); // [B, T, P, C]
        Ok(windows
            .into_iter()
            .enumerate()
            .map(|(i, (encoding, keyframe_latents, mask))| SampledWindow {
                encoding,
                keyframe_latents,
                mask,
                latents: latents.clone().narrow(0, i, 1),
            })
            .collect())
    }
}

impl WindowSampler for RfSampler {
    fn sample(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let s = self.sample_latents(clip, keyframes, caption, seed)?;
        self.models.codec.decode(&s.encoding, s.latents)
    }

    fn sample_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        self.sample_latents_batch(requests, caption)?
            .into_iter()
            .map(|s| self.models.codec.decode(&s.encoding, s.latents))
            .collect()
    }
}
