//! The VAE side of a learned method: one normalised window to VAE tensors (FPS on frame 0, edges, padding), its
//! encoding, and the decoded frames back as the window's real vertices.

use any4d_data::Clip;
use any4d_data::batch::PadTo;
use any4d_data::fps::farthest_point_sampling;
use any4d_data::preprocess::{edges_from_faces, pad_vertices};
use any4d_data::rng::splitmix64;
use any4d_model::any_vae::AnyMeshVae;
use any4d_model::mesh_vae::{EdgeList, MeshVae, VaeEncoding};
use burn::prelude::*;
use burn::tensor::TensorData;

use crate::error::{EvalError, Result};

use super::*;

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
    /// The P vertices of frame 0 whose features became the latent tokens (FPS, docs/method.md §2.5): the anchors of
    /// the scene's (S2).
    pub anchors: Vec<u32>,
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
            return Err(EvalError::invalid("mesh codec", "tokens", "P must be positive"));
        }
        if padding == PadTo::Fixed(0) {
            return Err(EvalError::invalid(
                "mesh codec",
                "padding",
                "a fixed vertex axis must be positive",
            ));
        }
        if vae.clip_frames() == Some(0) {
            return Err(EvalError::invalid(
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

    /// The P vertices of `clip`'s frame 0 that become its latent tokens (FPS, docs/method.md §2.5).
    pub fn anchors(&self, clip: &Clip) -> Vec<u32> {
        farthest_point_sampling(clip.frame(0), self.tokens)
    }

    /// Builds the batch-1 VAE input of `frames` of `clip`.
    fn input(&self, clip: &Clip, frames: &[usize]) -> Result<VaeInput> {
        clip.validate().map_err(|e| e.at(&clip.id))?;
        if let Some(&f) = frames.iter().find(|&&f| f >= clip.frames) {
            return Err(EvalError::invalid(
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
        let fps: Vec<i64> = self.anchors(clip).into_iter().map(i64::from).collect();
        let edges = edges_from_faces(&clip.faces, n_real).map_err(|e| e.at(&clip.id))?;
        let edges = EdgeList::new(&[edges], n, &self.device)
            .map_err(|e| EvalError::invalid(&clip.id, "faces", e.to_string()))?;
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
            return Err(EvalError::invalid(
                &clip.id,
                "frames",
                "nothing to encode: no frame was given",
            ));
        }
        if let Some(t) = self.vae.clip_frames() {
            let all: Vec<usize> = (0..clip.frames).collect();
            if clip.frames != t || frames != all.as_slice() {
                return Err(EvalError::invalid(
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
        let anchors = input
            .fps
            .clone()
            .into_data()
            .convert::<i64>()
            .try_into_vec::<i64>()
            .map_err(|e| EvalError::invalid(&clip.id, "fps", format!("cannot read the FPS indices: {e:?}")))?
            .into_iter()
            .map(|i| i as u32)
            .collect();
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
            anchors,
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
            return Err(EvalError::invalid(
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
            return Err(EvalError::invalid(&clip.id, "frames", "the window has no frame 0"));
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
    pub(crate) fn require_frame_wise(&self, what: &str) -> Result<()> {
        match self.vae {
            AnyMeshVae::Framewise(_) => Ok(()),
            AnyMeshVae::Sequencewise(_) => Err(EvalError::invalid(
                what,
                "vae",
                "needs the frame-wise VAE (one latent per frame), got the sequence-wise DyMeshVAE",
            )),
        }
    }
}

/// The first `n_real` rows of every frame of a decoded `[1, G, N, 3]` tensor, checked finite.
pub(crate) fn real_rows(x: Tensor<4>, n_real: usize, id: &str) -> Result<Vec<[f32; 3]>> {
    let [_, g, n, _] = x.dims();
    let flat = x
        .try_to_vec_as::<f32>()
        .map_err(|e| EvalError::invalid(id, "decoded vertices", format!("cannot read the tensor: {e:?}")))?;
    if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
        let row = i / 3;
        return Err(EvalError::invalid(
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
        return Err(EvalError::invalid(
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
        return Err(EvalError::invalid(
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
pub(crate) fn scatter_keyframes(
    enc: &WindowEncoding,
    keys: &[usize],
    device: &Device,
) -> Result<(Tensor<4>, Vec<f32>)> {
    let [_, k, p, c] = enc.mu.dims();
    let t = enc.window_frames;
    let mu = enc
        .mu
        .try_to_vec_as::<f32>()
        .map_err(|e| EvalError::invalid(&enc.id, "keyframe latents", format!("cannot read the tensor: {e:?}")))?;
    let len = p * c;
    let mut out = vec![0.0f32; t * len];
    let mut mask = vec![0.0f32; t];
    for &f in keys {
        let row = enc
            .frames
            .iter()
            .position(|&e| e == f)
            .filter(|&r| r < k)
            .ok_or_else(|| EvalError::invalid(&enc.id, "keyframes", format!("keyframe {f} was not encoded")))?;
        out[f * len..(f + 1) * len].copy_from_slice(&mu[row * len..(row + 1) * len]);
        mask[f] = 1.0;
    }
    Ok((Tensor::from_data(TensorData::new(out, [1, t, p, c]), device), mask))
}

/// Frames to encode for a keyframe set: frame 0 (the reference, always known) and the keyframes.
pub(crate) fn encoded_frames(keys: &[usize]) -> Vec<usize> {
    let mut frames = keys.to_vec();
    if frames.first() != Some(&0) {
        frames.insert(0, 0);
    }
    frames
}
