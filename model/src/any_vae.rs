//! A mesh VAE of either kind (docs/method.md §8 A3): the frame-wise VAE of the method or the sequence-wise
//! DyMeshVAE ablation, with their configs, for the code that serves both (training, latent statistics, loading
//! runs, evaluation).

use burn::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dymesh_vae::{DyMeshVae, DyMeshVaeConfig};
use crate::frame_vae::{FrameVae, FrameVaeConfig};
use crate::mesh_vae::{MeshVae, MeshVaeBody, MeshVaeBodyConfig};

/// Which mesh VAE (docs/method.md §8 A3): the `[vae] kind` of a VAE run config.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VaeKind {
    /// Frame-wise VAE (docs/method.md §3.2; the method's).
    Framewise,
    /// Sequence-wise DyMeshVAE (AnimateAnyMesh; ablation).
    Sequencewise,
}

/// The configuration of a mesh VAE of either kind.
#[derive(Clone, Debug, PartialEq)]
pub enum AnyMeshVaeConfig {
    /// A frame-wise VAE.
    Framewise(FrameVaeConfig),
    /// A sequence-wise DyMeshVAE.
    Sequencewise(DyMeshVaeConfig),
}

impl AnyMeshVaeConfig {
    /// Which kind.
    pub fn kind(&self) -> VaeKind {
        match self {
            Self::Framewise(_) => VaeKind::Framewise,
            Self::Sequencewise(_) => VaeKind::Sequencewise,
        }
    }

    /// The shared body's sizes.
    pub fn body(&self) -> &MeshVaeBodyConfig {
        match self {
            Self::Framewise(c) => &c.body,
            Self::Sequencewise(c) => &c.body,
        }
    }

    /// Latent channels C per slot.
    pub fn latent_channels(&self) -> usize {
        self.body().latent_channels
    }

    /// [`MeshVaeBodyConfig::activation_bytes`] of a training micro-batch of clips with `frames` frames (the
    /// frame-wise VAE's motion groups; the sequence-wise one encodes each clip as one trajectory group).
    pub fn activation_bytes(&self, micro_batch: usize, frames: usize, vertices: usize, tokens: usize) -> u128 {
        let groups = match self {
            Self::Framewise(_) => frames,
            Self::Sequencewise(_) => 1,
        };
        self.body().activation_bytes(micro_batch, groups, vertices, tokens)
    }

    /// Builds the VAE on `device`.
    pub fn init(&self, device: &Device) -> AnyMeshVae {
        match self {
            Self::Framewise(c) => AnyMeshVae::Framewise(c.init(device)),
            Self::Sequencewise(c) => AnyMeshVae::Sequencewise(c.init(device)),
        }
    }
}

/// A mesh VAE of either kind, for the code that serves both (evaluation, latent statistics, loading runs).
#[derive(Clone, Debug)]
pub enum AnyMeshVae {
    /// Frame-wise VAE: one trajectory latent per frame, `[B, T, P, C]`.
    Framewise(FrameVae),
    /// Sequence-wise DyMeshVAE: one latent per clip, `[B, 1, P, C]`.
    Sequencewise(DyMeshVae),
}

impl AnyMeshVae {
    /// Which kind.
    pub fn kind(&self) -> VaeKind {
        match self {
            Self::Framewise(_) => VaeKind::Framewise,
            Self::Sequencewise(_) => VaeKind::Sequencewise,
        }
    }

    /// The clip length a sequence-wise VAE was built for; `None` for the frame-wise VAE (any length).
    pub fn clip_frames(&self) -> Option<usize> {
        match self {
            Self::Framewise(_) => None,
            Self::Sequencewise(v) => Some(v.frames()),
        }
    }

    /// The same network without autodiff (for inference).
    pub fn valid(self) -> Self {
        match self {
            Self::Framewise(v) => Self::Framewise(v.valid()),
            Self::Sequencewise(v) => Self::Sequencewise(v.valid()),
        }
    }
}

impl MeshVae for AnyMeshVae {
    fn embed_motion(&self, offsets: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Framewise(v) => v.embed_motion(offsets),
            Self::Sequencewise(v) => v.embed_motion(offsets),
        }
    }

    fn frame_offsets(&self, decoded: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Framewise(v) => v.frame_offsets(decoded),
            Self::Sequencewise(v) => v.frame_offsets(decoded),
        }
    }

    fn kl_weight(&self) -> f64 {
        match self {
            Self::Framewise(v) => v.kl_weight(),
            Self::Sequencewise(v) => v.kl_weight(),
        }
    }

    fn body(&self) -> &MeshVaeBody {
        match self {
            Self::Framewise(v) => v.body(),
            Self::Sequencewise(v) => v.body(),
        }
    }
}
