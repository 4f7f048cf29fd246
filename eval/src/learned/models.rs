//! One trained RF checkpoint with its VAE, latent statistics and text encoder, checked to fit together.

use std::sync::Arc;

use any4d_model::latent_stats::LatentStats;
use any4d_model::mmdit::{KeyframeConditioning, Mmdit, MmditConfig};
use any4d_model::text::TextEncoder;

use crate::error::{EvalError, Result};

use super::*;

/// One trained RF checkpoint with everything it samples with: the frame-wise VAE (in a [`MeshCodec`], shareable
/// with [`LatentLerpSampler`]), the MMDiT and its config, the latent statistics of docs/method.md §3.4 and the text
/// encoder (the scratch encoder is trained jointly with the RF, so it comes from the same checkpoint).
pub struct LearnedModels {
    pub(super) codec: Arc<MeshCodec>,
    pub(super) rf: Mmdit,
    pub(super) rf_config: MmditConfig,
    pub(super) stats: LatentStats,
    pub(super) text: Box<dyn TextEncoder + Send + Sync>,
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
        let bad = |field: &str, reason: String| Err(EvalError::invalid("learned models", field, reason));
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
