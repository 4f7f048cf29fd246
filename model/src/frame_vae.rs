//! Frame-wise mesh VAE of CompletionAny4D (docs/method.md §3.1–§3.3): the shared body of `mesh_vae.rs` with a
//! per-frame motion input, so every frame gets its own trajectory latent z_f against the one reference mesh.

use burn::prelude::*;
use serde::{Deserialize, Serialize};

use crate::mesh_vae::{MeshVae, MeshVaeBody, MeshVaeBodyConfig, Posterior, VaeBatch, VaeEncoding};
use crate::point_embed::{OffsetEmbed, OffsetEmbedConfig};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameVaeConfig {
    /// Offset-embedding frequencies 2^j·π (10 → 63 Fourier values).
    pub offset_freqs: usize,
    /// KL weight β of (V3) (P-Table S4: 1e-4; AAM code 1e-6).
    pub kl_weight: f64,
    /// The shared body (`[model.body]`).
    pub body: MeshVaeBodyConfig,
}

impl FrameVaeConfig {
    /// The paper's size (P-Table S4): d 128, C 12.
    pub fn paper() -> Self {
        Self {
            offset_freqs: 10,
            kl_weight: 1e-4,
            body: MeshVaeBodyConfig::paper(128, 12),
        }
    }

    /// A small configuration for unit tests (d 32, 2 + 2 blocks, 2 heads of 16, C = 4).
    pub fn tiny() -> Self {
        Self {
            body: MeshVaeBodyConfig::tiny(),
            ..Self::paper()
        }
    }

    /// Checks the sizes; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.offset_freqs == 0 || self.kl_weight.is_nan() || self.kl_weight < 0.0 {
            return Err(format!(
                "model.offset_freqs must be positive and model.kl_weight non-negative, got {} and {}",
                self.offset_freqs, self.kl_weight
            ));
        }
        self.body.validate()?;
        let offset_embed = (6 * self.offset_freqs as u128 + 3) * self.body.width as u128;
        crate::summary::check_param_estimate(
            "model.body and model.offset_freqs",
            self.body.param_estimate() + offset_embed,
        )
    }

    /// Builds the VAE on `device`.
    pub fn init(&self, device: &Device) -> FrameVae {
        FrameVae {
            body: self.body.init(3, device),
            offset_embed: OffsetEmbedConfig::new(3, self.body.width)
                .with_offset_freqs(self.offset_freqs)
                .init(device),
            kl_weight: self.kl_weight,
        }
    }
}

/// Frame-wise mesh VAE (docs/method.md §3): the shape stream is computed once per clip, every frame's offset from the
/// reference is encoded into its own trajectory latent z_f with the same FPS tokens, and decoding predicts
/// each frame as the reference plus a per-vertex offset.
#[derive(Module, Debug)]
pub struct FrameVae {
    body: MeshVaeBody,
    offset_embed: OffsetEmbed,
    #[module(skip)]
    kl_weight: f64,
}

impl FrameVae {
    /// Encodes and decodes a batch (see [`MeshVae::reconstruct`]).
    ///
    /// # Shapes
    /// - returns `[B, T, N, 3]` and the encoding (`mu`/`logvar` `[B, T, P, C]`)
    pub fn reconstruct(&self, batch: &VaeBatch, posterior: Posterior) -> (Tensor<4>, VaeEncoding) {
        MeshVae::reconstruct(self, batch, posterior)
    }
}

impl MeshVae for FrameVae {
    /// Each frame's offset from the reference, embedded on its own: one motion group per frame.
    ///
    /// # Shapes
    /// - `offsets`: `[B, T, N, 3]` → `[B, T, N, D]`
    fn embed_motion(&self, offsets: Tensor<4>) -> Tensor<4> {
        self.offset_embed.forward(offsets)
    }

    /// The head decodes 3 values per frame: the offsets as they are.
    ///
    /// # Shapes
    /// - `decoded`: `[B, T, N, 3]` → `[B, T, N, 3]`
    fn frame_offsets(&self, decoded: Tensor<4>) -> Tensor<4> {
        decoded
    }

    fn kl_weight(&self) -> f64 {
        self.kl_weight
    }

    fn body(&self) -> &MeshVaeBody {
        &self.body
    }
}
