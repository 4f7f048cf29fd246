//! Sequence-wise DyMeshVAE (AnimateAnyMesh; docs/method.md §3.5 ablation): the whole clip's trajectory of each vertex
//! (all T offsets, 3T = 48 values → 1008 Fourier values) is encoded into one motion latent z_T per token.
//! Same body, losses (V1)–(V3) and API as the frame-wise VAE (`mesh_vae.rs`); only the motion embedding, the
//! latent size and the output head (3T values per vertex) differ.

use burn::prelude::*;
use serde::{Deserialize, Serialize};

use crate::mesh_vae::{MeshVae, MeshVaeBody, MeshVaeBodyConfig, Posterior, VaeBatch, VaeEncoding};
use crate::point_embed::{OffsetEmbed, OffsetEmbedConfig};

/// Configuration of the sequence-wise DyMeshVAE (docs/method.md §3.5 right column): the `[model]` table of a
/// sequence-wise `configs/vae/*.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DyMeshVaeConfig {
    /// Frames T of a clip; the trajectory input has 3T values (48).
    pub frames: usize,
    /// Trajectory-embedding frequencies 2^j·π (10 → 21·3T = 1008 Fourier values).
    pub offset_freqs: usize,
    /// KL weight β of (V3) (1e-4, as the frame-wise VAE; AAM code 1e-6).
    pub kl_weight: f64,
    /// The shared body (`[model.body]`).
    pub body: MeshVaeBodyConfig,
}

impl DyMeshVaeConfig {
    /// AnimateAnyMesh's size: d 256, C 32, T 16.
    pub fn paper() -> Self {
        Self {
            frames: 16,
            offset_freqs: 10,
            kl_weight: 1e-4,
            body: MeshVaeBodyConfig::paper(256, 32),
        }
    }

    /// A small configuration for unit tests (d 32, 2 + 2 blocks, 2 heads of 16, C = 4, T = 4).
    pub fn tiny() -> Self {
        Self {
            frames: 4,
            body: MeshVaeBodyConfig::tiny(),
            ..Self::paper()
        }
    }

    /// This configuration for clips of `frames` frames.
    pub fn with_frames(mut self, frames: usize) -> Self {
        self.frames = frames;
        self
    }

    /// Checks the sizes; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.frames == 0 || self.offset_freqs == 0 || self.kl_weight.is_nan() || self.kl_weight < 0.0 {
            return Err(format!(
                "model.frames and model.offset_freqs must be positive and model.kl_weight non-negative, got {}, {} \
                 and {}",
                self.frames, self.offset_freqs, self.kl_weight
            ));
        }
        self.body.validate()
    }

    /// Builds the VAE on `device`.
    pub fn init(&self, device: &Device) -> DyMeshVae {
        DyMeshVae {
            body: self.body.init(3 * self.frames, device),
            traj_embed: OffsetEmbedConfig::new(3 * self.frames, self.body.width)
                .with_offset_freqs(self.offset_freqs)
                .init(device),
            frames: self.frames,
            kl_weight: self.kl_weight,
        }
    }
}

/// Sequence-wise DyMeshVAE: one motion latent per token for the whole clip. Its `mu`/`logvar`/`z` carry a
/// group axis of size 1 (`[B, 1, P, C]`) so that it shares the frame-wise VAE's shapes and body.
#[derive(Module, Debug)]
pub struct DyMeshVae {
    body: MeshVaeBody,
    traj_embed: OffsetEmbed,
    #[module(skip)]
    frames: usize,
    #[module(skip)]
    kl_weight: f64,
}

impl DyMeshVae {
    /// The clip length T this VAE was built for.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Whole-clip reconstruction (see [`MeshVae::reconstruct`]); the encoding has one latent group.
    ///
    /// # Shapes
    /// - returns `[B, T, N, 3]` and the encoding (`mu`/`logvar` `[B, 1, P, C]`)
    pub fn reconstruct(&self, batch: &VaeBatch, posterior: Posterior) -> (Tensor<4>, VaeEncoding) {
        MeshVae::reconstruct(self, batch, posterior)
    }
}

impl MeshVae for DyMeshVae {
    /// The whole trajectory of each vertex, flattened with channel index t·3 + xyz, embedded once: one motion group.
    ///
    /// # Shapes
    /// - `offsets`: `[B, T, N, 3]` → `[B, 1, N, D]`
    ///
    /// # Panics
    /// If T differs from the configured `frames` (the trajectory embedding's width depends on it).
    fn embed_motion(&self, offsets: Tensor<4>) -> Tensor<4> {
        let [b, t, n, _] = offsets.dims();
        assert_eq!(
            t, self.frames,
            "DyMeshVae was built for {} frames, got {t}",
            self.frames
        );
        self.traj_embed
            .forward(offsets.swap_dims(1, 2).reshape([b, 1, n, 3 * t]))
    }

    /// The 3T-wide head holds every frame's offset: unflattened to frames.
    ///
    /// # Shapes
    /// - `decoded`: `[B, 1, N, 3T]` → `[B, T, N, 3]`
    fn frame_offsets(&self, decoded: Tensor<4>) -> Tensor<4> {
        let [b, _, n, _] = decoded.dims();
        decoded.reshape([b, n, self.frames, 3]).swap_dims(1, 2)
    }

    fn kl_weight(&self) -> f64 {
        self.kl_weight
    }

    fn body(&self) -> &MeshVaeBody {
        &self.body
    }
}
