//! Trained networks on the evaluation protocol (docs/method.md §4.6, §5.1, §5.2 `lerp_space = "latent"`, §5.4, §6.1,
//! (E4)): one window (batch 1) is encoded with the mesh VAE, completed by the keyframe RF ((R3)–(R6)), the
//! replacement baseline ((R7)–(R8)), impute-until-τ* ((R9)) or latent interpolation ((L1) on z), and decoded.
//!
//! [`MeshCodec`] turns a normalised window into VAE tensors (FPS on frame 0, edges from faces, padding) and back;
//! [`LearnedModels`] holds one RF checkpoint with its VAE, latent statistics and text encoder; [`RfSampler`],
//! [`LatentLerpSampler`], [`VaeOracleSampler`] and [`VaeReconstructor`] are the eval crate's [`WindowSampler`] /
//! [`Reconstructor`].

use std::sync::Arc;

use any4d_data::batch::PadTo;
use any4d_data::fps::farthest_point_sampling;
use any4d_data::preprocess::{edges_from_faces, pad_vertices};
use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};
use any4d_data::{Clip, DataError};
use any4d_model::any_vae::AnyMeshVae;
use any4d_model::bdlstm::{
    BdLstm, LatentCodec, MergeConfig, SegmentError, SegmentTry, bbox_diagonal, frame_distance, merge_segment,
};
use any4d_model::latent_stats::LatentStats;
use any4d_model::mesh_vae::{EdgeList, MeshVae, Posterior, VaeEncoding};
use any4d_model::mmdit::{KeyframeConditioning, Mmdit, MmditConfig, replace_keyframes};
pub use any4d_model::rectified_flow::sampler_noise;
use any4d_model::rectified_flow::{Conditioning, ReplaceNoise, SampleOptions, sample_mmdit};
use any4d_model::text::{TextEncoder, caption_keep};
use burn::prelude::*;
use burn::tensor::TensorData;

use crate::baselines::lerp_latents;
use crate::methods::{MethodKind, Request, WindowSampler};
use crate::tables::reconstruction::Reconstructor;

type Result<T, E = DataError> = std::result::Result<T, E>;

/// Batch-1 tensors of one window for a mesh VAE.
struct VaeInput {
    /// Reference mesh x̄₀ (frame 0), `[1, N, 3]`.
    reference: Tensor<3>,
    /// The encoded frames, `[1, K, N, 3]`.
    frames: Tensor<4>,
    vmask: Tensor<2, Bool>,
    fps: Tensor<2, Int>,
    edges: EdgeList,
}

/// What the encoder produced for one window, in raw (not standardized) latent units.
#[derive(Debug, Clone)]
pub struct WindowEncoding {
    /// Per-vertex shape features E₀ of the reference, `[1, N, D]` (N = padded vertex axis).
    pub e0: Tensor<3>,
    /// Padded reference mesh x̄₀, `[1, N, 3]`.
    pub reference: Tensor<3>,
    /// Shape latent z₀, `[1, P, C]`.
    pub z0: Tensor<3>,
    /// Posterior means μ (or the codec's seeded posterior samples, [`KeyPosterior`]), `[1, G, P, C]`: one per entry
    /// of `frames` (frame-wise) or one per clip (sequence-wise).
    pub mu: Tensor<4>,
    /// The clip frames whose μ is in `mu` (frame-wise), or all frames `0..T` (sequence-wise).
    pub frames: Vec<usize>,
    /// Real vertices N_v of the window.
    pub n_real: usize,
    /// Frames T of the window.
    pub window_frames: usize,
    /// Clip id, for error messages.
    pub id: String,
}

/// Which latent of the posterior N(μ, σ²) an encoded window hands on (keyframe latents, latent lerp, table 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KeyPosterior {
    /// z = μ (docs/method.md §4.6, the paper).
    #[default]
    Mean,
    /// z = μ + σ·ξ with ξ drawn from `seed`, the clip id and the frame index: the same window always gets the
    /// same draw, whatever else is in its batch. A VAE trained with a tiny KL weight can leave channels whose σ
    /// exceeds the prior's; its decoder and an RF trained on sampled latents then never saw μ there
    /// (experiments/2026-12-01-small).
    Sample { seed: u64 },
}

/// A mesh VAE applied to single normalised windows: FPS on frame 0 (docs/method.md §2.5), edges from faces, padding
/// (docs/method.md §2.4), encode, decode, and the real rows back.
pub struct MeshCodec {
    vae: AnyMeshVae,
    tokens: usize,
    padding: PadTo,
    device: Device,
    posterior: KeyPosterior,
}

impl MeshCodec {
    /// `tokens` = P FPS tokens (512 at paper size; a window with fewer vertices gets what
    /// [`farthest_point_sampling`] returns, its points repeated cyclically). `padding`: `PadTo::BatchMax` = the
    /// window's own N_v (enough for a VAE with masked padded keys), `PadTo::Fixed(4096)` for an AAM-style VAE
    /// that attends to padding. Give the VAE without autodiff (`model.valid()`).
    pub fn new(vae: AnyMeshVae, tokens: usize, padding: PadTo, device: Device) -> Result<Self> {
        if tokens == 0 {
            return Err(DataError::new("mesh codec", "tokens", "P must be positive"));
        }
        if padding == PadTo::Fixed(0) {
            return Err(DataError::new(
                "mesh codec",
                "padding",
                "a fixed vertex axis must be positive",
            ));
        }
        if vae.clip_frames() == Some(0) {
            return Err(DataError::new(
                "mesh codec",
                "frames",
                "the sequence-wise VAE needs T > 0",
            ));
        }
        Ok(Self {
            vae,
            tokens,
            padding,
            device,
            posterior: KeyPosterior::Mean,
        })
    }

    /// The same codec handing on `posterior` latents from [`Self::encode`].
    pub fn with_posterior(mut self, posterior: KeyPosterior) -> Self {
        self.posterior = posterior;
        self
    }

    /// Which posterior latent [`Self::encode`] hands on.
    pub fn posterior(&self) -> KeyPosterior {
        self.posterior
    }

    /// The VAE.
    pub fn vae(&self) -> &AnyMeshVae {
        &self.vae
    }

    /// P.
    pub fn tokens(&self) -> usize {
        self.tokens
    }

    /// Where the tensors live.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Builds the batch-1 VAE input of `frames` of `clip`.
    fn input(&self, clip: &Clip, frames: &[usize]) -> Result<VaeInput> {
        clip.validate().map_err(|e| e.at(&clip.id))?;
        if let Some(&f) = frames.iter().find(|&&f| f >= clip.frames) {
            return Err(DataError::new(
                &clip.id,
                "keyframes",
                format!("frame {f} is outside the window of {} frames", clip.frames),
            ));
        }
        let n_real = clip.n_vertices;
        let n = match self.padding {
            PadTo::BatchMax => n_real,
            PadTo::Fixed(n) => n,
        };
        let reference_rows = clip.frame(0);
        let fps: Vec<i64> = farthest_point_sampling(reference_rows, self.tokens)
            .into_iter()
            .map(i64::from)
            .collect();
        let edges = edges_from_faces(&clip.faces, n_real).map_err(|e| e.at(&clip.id))?;
        let edges =
            EdgeList::new(&[edges], n, &self.device).map_err(|e| DataError::new(&clip.id, "faces", e.to_string()))?;
        let (reference, vmask) = pad_vertices(reference_rows, n_real, 1, n).map_err(|e| e.at(&clip.id))?;
        let rows: Vec<[f32; 3]> = frames.iter().flat_map(|&f| clip.frame(f).iter().copied()).collect();
        let (selected, _) = pad_vertices(&rows, n_real, frames.len(), n).map_err(|e| e.at(&clip.id))?;
        let d = &self.device;
        Ok(VaeInput {
            reference: Tensor::from_data(TensorData::new(reference, [1, n, 3]), d),
            frames: Tensor::from_data(TensorData::new(selected, [1, frames.len(), n, 3]), d),
            vmask: Tensor::from_data(TensorData::new(vmask, [1, n]), d),
            fps: Tensor::from_data(TensorData::new(fps, [1, self.tokens]), d),
            edges,
        })
    }

    /// Encodes `frames` of a normalised window against its frame 0 and returns the posterior means (or seeded
    /// posterior samples, see [`KeyPosterior`]). The sequence-wise VAE encodes the whole window, so `frames` must
    /// then be `0..T` (T as it was built for).
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N_v]` rows; returns `mu` `[1, G, P, C]` with G = `frames.len()` (frame-wise) or 1.
    pub fn encode(&self, clip: &Clip, frames: &[usize]) -> Result<WindowEncoding> {
        if frames.is_empty() {
            return Err(DataError::new(
                &clip.id,
                "frames",
                "nothing to encode: no frame was given",
            ));
        }
        if let Some(t) = self.vae.clip_frames() {
            let all: Vec<usize> = (0..clip.frames).collect();
            if clip.frames != t || frames != all.as_slice() {
                return Err(DataError::new(
                    &clip.id,
                    "frames",
                    format!(
                        "the sequence-wise VAE encodes whole windows of {t} frames; got frames {frames:?} of a \
                         {}-frame window",
                        clip.frames
                    ),
                ));
            }
        }
        let input = self.input(clip, frames)?;
        let reference = input.reference.clone();
        let VaeEncoding { e0, z0, mu, logvar } =
            self.vae
                .encode(input.reference, input.frames, input.vmask, input.fps, &input.edges);
        let mu = match self.posterior {
            KeyPosterior::Mean => mu,
            KeyPosterior::Sample { seed } => {
                let [_, g, p, c] = mu.dims();
                let clip_seed = clip
                    .id
                    .bytes()
                    .fold(splitmix64(seed), |h, b| splitmix64(h ^ u64::from(b)));
                let noise = (0..g)
                    .map(|i| {
                        let frame = if g == frames.len() { frames[i] } else { i };
                        sampler_noise(splitmix64(clip_seed ^ frame as u64), [1, 1, p, c], &self.device)
                    })
                    .collect();
                mu + logvar.mul_scalar(0.5).exp() * Tensor::cat(noise, 1)
            }
        };
        Ok(WindowEncoding {
            e0,
            reference,
            z0,
            mu,
            frames: frames.to_vec(),
            n_real: clip.n_vertices,
            window_frames: clip.frames,
            id: clip.id.clone(),
        })
    }

    /// Decodes trajectory latents against the encoded reference: x̂ = x̄₀ + offsets (docs/method.md §3.2 "Output"),
    /// real rows only.
    ///
    /// # Shapes
    /// `z`: `[1, G, P, C]` raw latents (frame-wise: G frames in order; sequence-wise: G = 1); returns
    /// `[G, N_v]` rows (frame-wise) or `[T, N_v]` rows (sequence-wise).
    pub fn decode(&self, enc: &WindowEncoding, z: Tensor<4>) -> Result<Vec<[f32; 3]>> {
        let [_, p, c] = enc.z0.dims();
        let [b, _, pz, cz] = z.dims();
        if b != 1 || pz != p || cz != c {
            return Err(DataError::new(
                &enc.id,
                "latents",
                format!("shape {:?} does not match the encoding's [1, G, {p}, {c}]", z.dims()),
            ));
        }
        let x = self
            .vae
            .decode(enc.e0.clone(), enc.reference.clone(), enc.z0.clone(), z);
        real_rows(x, enc.n_real, &enc.id)
    }

    /// Encodes the reference (frame 0) of a normalised window and nothing else: E₀, x̄₀ and z₀ for decoding, as a
    /// model conditioned on the reference mesh alone needs (the AnimateAnyMesh reference, docs/method.md §5.5). No
    /// other frame of `clip` is read: the encoder sees frame 0 held still for `frames` frames (frame-wise VAE: frame
    /// 0 alone), so `mu` is the motion latent of a motionless window.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N_v]` rows (only frame 0 read); returns `mu` `[1, 1, P, C]`.
    pub fn encode_reference(&self, clip: &Clip) -> Result<WindowEncoding> {
        let Some(frames) = self.vae.clip_frames() else {
            return self.encode(clip, &[0]);
        };
        if clip.frames == 0 {
            return Err(DataError::new(&clip.id, "frames", "the window has no frame 0"));
        }
        let still = Clip {
            vertices: clip.frame(0).repeat(frames),
            frames,
            ..clip.clone()
        };
        let all: Vec<usize> = (0..frames).collect();
        self.encode(&still, &all)
    }

    /// (E4) encode → posterior mean (or the codec's [`KeyPosterior`]) → decode of every frame of a normalised window
    /// (P-Table 5).
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N_v]` rows; returns `[T, N_v]` rows.
    pub fn reconstruct(&self, clip: &Clip) -> Result<Vec<[f32; 3]>> {
        let all: Vec<usize> = (0..clip.frames).collect();
        let enc = self.encode(clip, &all)?;
        let mu = enc.mu.clone();
        self.decode(&enc, mu)
    }

    /// The frame-wise VAE, or an error naming `what` needs it.
    fn require_frame_wise(&self, what: &str) -> Result<()> {
        match self.vae {
            AnyMeshVae::Framewise(_) => Ok(()),
            AnyMeshVae::Sequencewise(_) => Err(DataError::new(
                what,
                "vae",
                "needs the frame-wise VAE (one latent per frame), got the sequence-wise DyMeshVAE",
            )),
        }
    }
}

/// The first `n_real` rows of every frame of a decoded `[1, G, N, 3]` tensor, checked finite.
fn real_rows(x: Tensor<4>, n_real: usize, id: &str) -> Result<Vec<[f32; 3]>> {
    let [_, g, n, _] = x.dims();
    let flat = x
        .try_to_vec_as::<f32>()
        .map_err(|e| DataError::new(id, "decoded vertices", format!("cannot read the tensor: {e:?}")))?;
    if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
        let row = i / 3;
        return Err(DataError::new(
            id,
            "decoded vertices",
            format!("non-finite value {} at frame {}, vertex {}", flat[i], row / n, row % n),
        ));
    }
    Ok((0..g)
        .flat_map(|f| (0..n_real).map(move |v| f * n + v))
        .map(|r| [flat[3 * r], flat[3 * r + 1], flat[3 * r + 2]])
        .collect())
}

/// Sorted, deduplicated keyframes, each inside the window.
pub(crate) fn keyframe_list(clip: &Clip, keyframes: &[usize]) -> Result<Vec<usize>> {
    let mut keys = keyframes.to_vec();
    keys.sort_unstable();
    keys.dedup();
    if let Some(&f) = keys.iter().find(|&&f| f >= clip.frames) {
        return Err(DataError::new(
            &clip.id,
            "keyframes",
            format!("frame {f} is outside the window of {} frames", clip.frames),
        ));
    }
    Ok(keys)
}

/// [`keyframe_list`] for a method that completes between keyframes: frames 0 and T − 1 must be among them.
pub(crate) fn end_keyframes(clip: &Clip, keyframes: &[usize]) -> Result<Vec<usize>> {
    let keys = keyframe_list(clip, keyframes)?;
    let t = clip.frames;
    if keys.first() != Some(&0) || keys.last() != Some(&(t - 1)) {
        return Err(DataError::new(
            &clip.id,
            "keyframes",
            format!(
                "BD-LSTM completes between keyframes: frames 0 and {} must be keyframes, got {keys:?}",
                t - 1
            ),
        ));
    }
    Ok(keys)
}

/// Keyframe latents laid out over all T frames (zero elsewhere) and the mask m.
///
/// # Shapes
/// `enc.mu`: `[1, K, P, C]` for `enc.frames`; returns `[1, T, P, C]` and `[T]`.
fn scatter_keyframes(enc: &WindowEncoding, keys: &[usize], device: &Device) -> Result<(Tensor<4>, Vec<f32>)> {
    let [_, k, p, c] = enc.mu.dims();
    let t = enc.window_frames;
    let mu = enc
        .mu
        .try_to_vec_as::<f32>()
        .map_err(|e| DataError::new(&enc.id, "keyframe latents", format!("cannot read the tensor: {e:?}")))?;
    let len = p * c;
    let mut out = vec![0.0f32; t * len];
    let mut mask = vec![0.0f32; t];
    for &f in keys {
        let row = enc
            .frames
            .iter()
            .position(|&e| e == f)
            .filter(|&r| r < k)
            .ok_or_else(|| DataError::new(&enc.id, "keyframes", format!("keyframe {f} was not encoded")))?;
        out[f * len..(f + 1) * len].copy_from_slice(&mu[row * len..(row + 1) * len]);
        mask[f] = 1.0;
    }
    Ok((Tensor::from_data(TensorData::new(out, [1, t, p, c]), device), mask))
}

/// Frames to encode for a keyframe set: frame 0 (the reference, always known) and the keyframes.
fn encoded_frames(keys: &[usize]) -> Vec<usize> {
    let mut frames = keys.to_vec();
    if frames.first() != Some(&0) {
        frames.insert(0, 0);
    }
    frames
}

/// One trained RF checkpoint with everything it samples with: the frame-wise VAE (in a [`MeshCodec`], shareable
/// with [`LatentLerpSampler`]), the MMDiT and its config, the latent statistics of docs/method.md §3.4 and the text
/// encoder (the scratch encoder is trained jointly with the RF, so it comes from the same checkpoint).
pub struct LearnedModels {
    codec: Arc<MeshCodec>,
    rf: Mmdit,
    rf_config: MmditConfig,
    stats: LatentStats,
    text: Box<dyn TextEncoder + Send + Sync>,
}

impl LearnedModels {
    /// Checks that the parts fit together: frame-wise VAE, the network built from `rf_config`, the text width,
    /// usable statistics. Give networks without autodiff (`model.valid()`).
    pub fn new(
        codec: Arc<MeshCodec>,
        rf: Mmdit,
        rf_config: MmditConfig,
        stats: LatentStats,
        text: Box<dyn TextEncoder + Send + Sync>,
    ) -> Result<Self> {
        let bad = |field: &str, reason: String| Err(DataError::new("learned models", field, reason));
        if codec.vae().clip_frames().is_some()
            && (rf_config.frames != 1 || rf_config.conditioning != KeyframeConditioning::None)
        {
            return bad(
                "rf config",
                format!(
                    "an RF on the sequence-wise VAE (the AnimateAnyMesh reference) has one trajectory slot and no \
                     keyframes: needs frames = 1 and conditioning none, got frames = {} and {:?}",
                    rf_config.frames, rf_config.conditioning
                ),
            );
        }
        if let Err(msg) = rf_config.validate() {
            return bad("rf config", msg);
        }
        if rf.in_channels() != rf_config.in_channels() {
            return bad(
                "rf",
                format!(
                    "the network takes {} input channels, its config ({:?}, T = {}, C = {}) gives {}",
                    rf.in_channels(),
                    rf_config.conditioning,
                    rf_config.frames,
                    rf_config.channels,
                    rf_config.in_channels()
                ),
            );
        }
        if text.dim() != rf_config.text_dim {
            return bad(
                "text",
                format!(
                    "the encoder gives width {}, the RF expects text_dim {}",
                    text.dim(),
                    rf_config.text_dim
                ),
            );
        }
        for (name, mean, std) in [
            ("shape", stats.shape_mean, stats.shape_std),
            ("motion", stats.motion_mean, stats.motion_std),
        ] {
            if !(mean.is_finite() && std.is_finite() && std > 0.0) {
                return bad(
                    "stats",
                    format!("{name} mean {mean} / std {std}: std must be finite and > 0"),
                );
            }
        }
        Ok(Self {
            codec,
            rf,
            rf_config,
            stats,
            text,
        })
    }

    /// The VAE codec (share it with a [`LatentLerpSampler`] or [`VaeReconstructor`]).
    pub fn codec(&self) -> &Arc<MeshCodec> {
        &self.codec
    }

    /// The RF's config.
    pub fn rf_config(&self) -> &MmditConfig {
        &self.rf_config
    }

    /// The latent statistics.
    pub fn stats(&self) -> &LatentStats {
        &self.stats
    }
}

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
        let bad = |field: &str, reason: String| Err(DataError::new("rf sampler", field, reason));
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
                return Err(DataError::new(
                    "rf sampler",
                    other.label(),
                    "is not a rectified-flow method",
                ));
            }
        };
        let sequencewise = models.codec.vae().clip_frames().is_some();
        if (kind == MethodKind::Aam) != sequencewise {
            let reason = if sequencewise {
                "needs an RF trained on a frame-wise VAE; this one is the AnimateAnyMesh reference (an RF on the \
                 sequence-wise VAE that takes no keyframes): it runs only as method `aam` of `eval run`"
            } else {
                "needs the AnimateAnyMesh reference, an RF trained on a sequence-wise VAE (configs/rf/aam_*.toml); \
                 this RF was trained on a frame-wise VAE"
            };
            return Err(DataError::new("rf sampler", kind.label(), reason));
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

    /// Samples the trajectory latents of one window. Only frame 0 and the `keyframes` of `clip` are read.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N_v]` rows; `latents` `[1, T, P, C]`.
    pub fn sample_latents(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<SampledWindow> {
        let mut out = self.sample_latents_batch(&[Request { clip, keyframes, seed }], caption)?;
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
                return Err(DataError::new(
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
                return Err(DataError::new(
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
        };
        let text = m
            .text
            .encode(&[caption.to_string()], &device)
            .map_err(|e| DataError::new(&first.id, "caption", e.to_string()))?
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

/// (L1) in latent space (docs/method.md §5.2, `lerp_space = "latent"`): the keyframes' posterior means are interpolated
/// between consecutive keyframes, then every frame is decoded. Frames 0 and T − 1 must be keyframes.
pub struct LatentLerpSampler {
    codec: Arc<MeshCodec>,
}

impl LatentLerpSampler {
    /// Needs the frame-wise VAE.
    pub fn new(codec: Arc<MeshCodec>) -> Result<Self> {
        codec.require_frame_wise("latent lerp")?;
        Ok(Self { codec })
    }

    /// The interpolated latents of one window and the encoding to decode them with.
    ///
    /// # Shapes
    /// returns latents `[1, T, P, C]`.
    pub fn latents(&self, clip: &Clip, keyframes: &[usize]) -> Result<(WindowEncoding, Tensor<4>)> {
        let keys = keyframe_list(clip, keyframes)?;
        let enc = self.codec.encode(clip, &encoded_frames(&keys))?;
        let (z, _) = scatter_keyframes(&enc, &keys, self.codec.device())?;
        let [_, t, p, c] = z.dims();
        let flat = z
            .try_to_vec_as::<f32>()
            .map_err(|e| DataError::new(&clip.id, "keyframe latents", format!("cannot read the tensor: {e:?}")))?;
        // (L1) on z: ẑ_f = z_a + (f − a)/(b − a) · (z_b − z_a)
        let filled =
            lerp_latents(&flat, t, p * c, &keys).map_err(|e| DataError::new(&clip.id, "lerp_latent", e.to_string()))?;
        let z = Tensor::from_data(TensorData::new(filled, [1, t, p, c]), self.codec.device());
        Ok((enc, z))
    }
}

impl WindowSampler for LatentLerpSampler {
    fn sample(&self, clip: &Clip, keyframes: &[usize], _caption: &str, _seed: u64) -> Result<Vec<[f32; 3]>> {
        let (enc, z) = self.latents(clip, keyframes)?;
        self.codec.decode(&enc, z)
    }
}

/// The `vae_oracle` row (not a completion method): every frame of the ground-truth window encoded (posterior mean)
/// and decoded, the window's keyframes ignored. It reads the frames a completion method must generate, so it is the
/// floor of every latent method on this VAE under table 1's scoring.
pub struct VaeOracleSampler {
    codec: Arc<MeshCodec>,
}

impl VaeOracleSampler {
    /// Any VAE (frame-wise or sequence-wise).
    pub fn new(codec: Arc<MeshCodec>) -> Self {
        Self { codec }
    }
}

impl WindowSampler for VaeOracleSampler {
    fn sample(&self, clip: &Clip, _keyframes: &[usize], _caption: &str, _seed: u64) -> Result<Vec<[f32; 3]>> {
        self.codec.reconstruct(clip)
    }
}

/// A VAE row of P-Table 5: (E4) encode → posterior mean → decode.
pub struct VaeReconstructor {
    label: String,
    codec: Arc<MeshCodec>,
}

impl VaeReconstructor {
    /// `label` names the row, e.g. `framewise` or `sequencewise`.
    pub fn new(label: impl Into<String>, codec: Arc<MeshCodec>) -> Self {
        Self {
            label: label.into(),
            codec,
        }
    }
}

impl Reconstructor for VaeReconstructor {
    fn label(&self) -> String {
        self.label.clone()
    }

    fn reconstruct(&self, clip: &Clip) -> Result<Vec<[f32; 3]>> {
        self.codec.reconstruct(clip)
    }
}

/// The BD-LSTM baseline, latent adaptation (docs/method.md §5.3): between each pair of consecutive keyframes a < b
/// the forward chain runs from z_a and the backward chain from z_b (standardised latents, posterior means), both
/// are decoded, and the merge rule switches from the forward to the backward chain at the aligned pair that agrees
/// best, retrying with perturbed initial states (device RNG seeded from the sampler seed and a) until that pair is
/// within the threshold. Frames 0 and T − 1 must be keyframes.
pub struct BdlstmSampler {
    codec: Arc<MeshCodec>,
    model: BdLstm<LatentCodec>,
    stats: LatentStats,
    merge: MergeConfig,
}

/// An error inside one segment's merge of a BD-LSTM row: the rule's own or the decoder's / reconstruction's.
pub(crate) enum SegmentFailure {
    Rule(SegmentError),
    Data(DataError),
}

impl From<SegmentError> for SegmentFailure {
    fn from(e: SegmentError) -> Self {
        Self::Rule(e)
    }
}

impl BdlstmSampler {
    /// Needs the frame-wise VAE the BD-LSTM was trained on (its statistics standardise the latents). Give the network
    /// without autodiff, on the codec's device.
    pub fn new(
        codec: Arc<MeshCodec>,
        model: BdLstm<LatentCodec>,
        stats: LatentStats,
        merge: MergeConfig,
    ) -> Result<Self> {
        codec.require_frame_wise("BD-LSTM")?;
        Ok(Self {
            codec,
            model,
            stats,
            merge,
        })
    }

    /// Fills one segment a..=b (n = b − a + 1 ≥ 3 frames) from its standardised end latents `[1, P, C]`; returns
    /// the n latents in time order.
    fn segment(
        &self,
        enc: &WindowEncoding,
        clip: &Clip,
        (a, b): (usize, usize),
        (za, zb): (Tensor<3>, Tensor<3>),
        seed: u64,
    ) -> Result<Vec<Tensor<3>>> {
        let n = b - a + 1;
        let device = self.codec.device();
        device.seed(splitmix64(seed ^ (a as u64).wrapping_mul(GOLDEN_GAMMA)));
        let nv = clip.n_vertices;
        let diag = bbox_diagonal(&clip.vertices[a * nv..(a + 1) * nv]);
        let id = clip.id.as_str();
        let frames_of = |chain: Tensor<4>| -> Vec<Tensor<3>> {
            let [_, len, p, c] = chain.dims();
            (0..len)
                .map(|i| chain.clone().narrow(1, i, 1).reshape([1, p, c]))
                .collect()
        };
        let merged = merge_segment(&self.merge, |attempt| -> std::result::Result<_, SegmentFailure> {
            let init = self.model.retry_states(attempt, 1, device);
            let forward = self
                .model
                .chain(za.clone(), n - 1, init.forward, &(), Posterior::Mean)
                .frames;
            let backward = self
                .model
                .chain(zb.clone(), n - 1, init.backward, &(), Posterior::Mean)
                .frames
                .flip([1]);
            let decode = |z: Tensor<4>| {
                self.codec
                    .decode(enc, self.stats.destandardize_motion(z))
                    .map_err(SegmentFailure::Data)
            };
            let (vf, vb) = (decode(forward.clone())?, decode(backward.clone())?);
            let distances = (0..n)
                .map(|i| frame_distance(&vf[i * nv..(i + 1) * nv], &vb[i * nv..(i + 1) * nv], diag))
                .collect::<std::result::Result<Vec<f64>, SegmentError>>()?;
            Ok(SegmentTry::new(frames_of(forward), frames_of(backward), distances)?)
        })
        .map_err(|e| match e {
            SegmentFailure::Rule(e) => DataError::new(id, "bdlstm", e.to_string()),
            SegmentFailure::Data(e) => e,
        })?;
        Ok(merged.frames)
    }
}

impl WindowSampler for BdlstmSampler {
    fn sample(&self, clip: &Clip, keyframes: &[usize], _caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let keys = end_keyframes(clip, keyframes)?;
        let t = clip.frames;
        let enc = self.codec.encode(clip, &encoded_frames(&keys))?;
        let (z, _) = scatter_keyframes(&enc, &keys, self.codec.device())?;
        let z = self.stats.standardize_motion(z);
        let [_, _, p, c] = z.dims();
        let frame = |f: usize| z.clone().narrow(1, f, 1).reshape([1, p, c]);
        let mut out: Vec<Option<Tensor<3>>> = vec![None; t];
        for pair in keys.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let filled = if b - a + 1 >= 3 {
                self.segment(&enc, clip, (a, b), (frame(a), frame(b)), seed)?
            } else {
                vec![frame(a), frame(b)]
            };
            for (i, zf) in filled.into_iter().enumerate() {
                out[a + i] = Some(zf);
            }
        }
        let frames: Vec<Tensor<3>> = out
            .into_iter()
            .map(|f| f.expect("consecutive keyframe segments cover 0..T"))
            .collect();
        let z = self
            .stats
            .destandardize_motion(Tensor::stack::<4>(frames, 1).reshape([1, t, p, c]));
        self.codec.decode(&enc, z)
    }
}
