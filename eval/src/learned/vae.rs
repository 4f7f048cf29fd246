//! Methods of the VAE alone: latent interpolation (docs/method.md §5.2), the VAE oracle and the reconstruction of
//! table 5 ((E4)).

use std::sync::Arc;

use any4d_data::Clip;
use burn::prelude::*;
use burn::tensor::TensorData;

use crate::baselines::lerp_latents;
use crate::methods::WindowSampler;
use crate::tables::reconstruction::Reconstructor;

use crate::error::{EvalError, Result};

use super::*;

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
            .map_err(|e| EvalError::invalid(&clip.id, "keyframe latents", format!("cannot read the tensor: {e:?}")))?;
        // (L1) on z: ẑ_f = z_a + (f − a)/(b − a) · (z_b − z_a)
        let filled = lerp_latents(&flat, t, p * c, &keys)
            .map_err(|e| EvalError::invalid(&clip.id, "lerp_latent", e.to_string()))?;
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

    fn anchors(&self, clip: &Clip) -> Option<Vec<u32>> {
        Some(self.codec.anchors(clip))
    }
}
