//! Sequence-wise DyMeshVAE (AnimateAnyMesh; docs/method.md §3.5 ablation): the whole clip's trajectory of each vertex
//! (all T offsets, 3T = 48 values → 1008 Fourier values) is encoded into one motion latent z_T per token.
//! Same body, losses (V1)–(V3) and API as the frame-wise VAE (`frame_vae.rs`); only the motion embedding,
//! the latent size and the output head (3T values per vertex) differ.

use burn::prelude::*;

use crate::frame_vae::{
    EdgeList, MeshVaeBody, MeshVaeBodyConfig, MeshVaeModel, PadKeys, Posterior, VaeBatch, VaeEncoding,
};
use crate::point_embed::{OffsetEmbed, OffsetEmbedConfig};

/// Configuration of the sequence-wise DyMeshVAE (docs/method.md §3.5 right column; AAM defaults).
#[derive(Config, Debug)]
pub struct DyMeshVaeConfig {
    /// Width d (256).
    #[config(default = 256)]
    pub width: usize,
    /// Decoder self-attention heads (8).
    #[config(default = 8)]
    pub heads: usize,
    /// Decoder head width (64).
    #[config(default = 64)]
    pub head_dim: usize,
    /// Encoder cross-attention blocks (8); the encoder attention is one head of width d.
    #[config(default = 8)]
    pub enc_blocks: usize,
    /// Decoder self-attention blocks (8).
    #[config(default = 8)]
    pub dec_blocks: usize,
    /// Latent channels per stream (32): z₀ 32 + z_T 32 per token.
    #[config(default = 32)]
    pub latent_channels: usize,
    /// Frames T of a clip; the trajectory input has 3T values (48).
    #[config(default = 16)]
    pub frames: usize,
    /// Point-embedding frequencies 2^k·π (8).
    #[config(default = 8)]
    pub point_freqs: usize,
    /// Trajectory-embedding frequencies 2^j·π (10 → 21·3T = 1008 Fourier values).
    #[config(default = 10)]
    pub offset_freqs: usize,
    /// GEGLU multiple m: d → 2m·d, gate → m·d → d (4).
    #[config(default = 4)]
    pub ffn_mult: usize,
    /// Padded vertices as encoder keys (docs/method.md §9 item 15): masked (ours) or visible (AAM).
    #[config(default = "PadKeys::Masked")]
    pub pad_keys: PadKeys,
    /// Lower clamp of log σ² (−30).
    #[config(default = -30.0)]
    pub logvar_min: f64,
    /// Upper clamp of log σ² (20).
    #[config(default = 20.0)]
    pub logvar_max: f64,
    /// KL weight β of (V3) (1e-4, as the frame-wise VAE; AAM code 1e-6).
    #[config(default = 1e-4)]
    pub kl_weight: f64,
}

impl DyMeshVaeConfig {
    /// A small configuration for unit tests (d 32, 2 + 2 blocks, 2 heads of 16, C = 4, T = 4).
    pub fn tiny() -> Self {
        Self::new()
            .with_width(32)
            .with_heads(2)
            .with_head_dim(16)
            .with_enc_blocks(2)
            .with_dec_blocks(2)
            .with_latent_channels(4)
            .with_frames(4)
    }

    /// Builds the VAE on `device`.
    pub fn init(&self, device: &Device) -> DyMeshVae {
        let body = MeshVaeBodyConfig {
            width: self.width,
            heads: self.heads,
            head_dim: self.head_dim,
            enc_blocks: self.enc_blocks,
            dec_blocks: self.dec_blocks,
            latent_channels: self.latent_channels,
            point_freqs: self.point_freqs,
            ffn_mult: self.ffn_mult,
            pad_keys: self.pad_keys,
            logvar_min: self.logvar_min,
            logvar_max: self.logvar_max,
            out_per_group: 3 * self.frames,
        };
        DyMeshVae {
            body: body.init(device),
            traj_embed: OffsetEmbedConfig::new(3 * self.frames, self.width)
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
    /// Whole-clip reconstruction (see [`MeshVaeModel::reconstruct`]); the encoding has one latent group.
    ///
    /// # Shapes
    /// - returns `[B, T, N, 3]` and the encoding (`mu`/`logvar` `[B, 1, P, C]`)
    pub fn reconstruct(&self, batch: &VaeBatch, posterior: Posterior) -> (Tensor<4>, VaeEncoding) {
        MeshVaeModel::reconstruct(self, batch, posterior)
    }
}

impl MeshVaeModel for DyMeshVae {
    /// Encodes the whole clip's trajectories.
    ///
    /// # Shapes
    /// - `reference`: `[B, N, 3]`, `frames`: `[B, T, N, 3]`, `vmask`: `[B, N]`, `fps`: `[B, P]`
    /// - returns `e0` `[B, N, D]`, `z0` `[B, P, C]`, `mu`/`logvar` `[B, 1, P, C]`
    ///
    /// # Panics
    /// If T differs from the configured `frames` (the trajectory embedding's width depends on it).
    fn encode(
        &self,
        reference: Tensor<3>,
        frames: Tensor<4>,
        vmask: Tensor<2, Bool>,
        fps: Tensor<2, Int>,
        edges: &EdgeList,
    ) -> VaeEncoding {
        let [b, t, n, _] = frames.dims();
        assert_eq!(
            t, self.frames,
            "DyMeshVae was built for {} frames, got {t}",
            self.frames
        );
        let e0 = self.encode_shape(reference.clone(), edges);
        // Trajectory r = x̄_t − x̄₀ flattened per vertex with channel index t·3 + xyz (frame 0 included).
        let offsets = (frames - reference.unsqueeze_dim(1))
            .swap_dims(1, 2)
            .reshape([b, 1, n, 3 * t]);
        let motion = self.traj_embed.forward(offsets);
        let (z0, mu, logvar) = self.body.encode_tokens(e0.clone(), motion, vmask, fps);
        VaeEncoding { e0, z0, mu, logvar }
    }

    /// Decodes all frames: x̂_{t,v} = x̄_{0,v} + o_{t,v}, the T offsets read from one 3T-wide head.
    ///
    /// # Shapes
    /// - `e0`: `[B, N, D]`, `reference`: `[B, N, 3]`, `z0`: `[B, P, C]`, `z`: `[B, 1, P, C]`
    /// - returns `[B, T, N, 3]`
    fn decode(&self, e0: Tensor<3>, reference: Tensor<3>, z0: Tensor<3>, z: Tensor<4>) -> Tensor<4> {
        let [b, n, _] = reference.dims();
        let offsets = self
            .body
            .decode_offsets(e0, z0, z)
            .reshape([b, n, self.frames, 3])
            .swap_dims(1, 2);
        reference.unsqueeze_dim(1) + offsets
    }

    fn kl_weight(&self) -> f64 {
        self.kl_weight
    }

    fn body(&self) -> &MeshVaeBody {
        &self.body
    }
}
