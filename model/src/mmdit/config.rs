//! The MMDiT's configuration (docs/method.md §4.3, §8): keyframe conditioning, output and anchor, sizes, their
//! checks, and building the network with AnimateAnyMesh's initialisation.

use burn::nn::{Initializer, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Mmdit, MmditBlock, SceneConditioning, TIME_FREQS, TimestepEmbedder};

/// How keyframes condition the network (docs/method.md §8 A1, X2: `model.conditioning`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeyframeConditioning {
    /// Trained masked conditioning (the paper's method): clean keyframes + mask channels, 221 inputs (R3).
    InputMask,
    /// Sampling-time replacement with noised keyframes on the non-keyframe network, 204 inputs (R7)–(R8).
    ReplaceNoised,
    /// SceneMI imputation with noisy keyframes until τ* (R9); mask channels kept, 221 inputs.
    ImputeUntil,
    /// No keyframes at all (AnimateAnyMesh-style), 204 inputs.
    None,
}

impl KeyframeConditioning {
    /// Whether the input carries one mask channel per slot.
    pub fn has_mask_channels(self) -> bool {
        matches!(
            self,
            KeyframeConditioning::InputMask | KeyframeConditioning::ImputeUntil
        )
    }

    /// Whether `build_input` overwrites keyframe slots with the given keyframe latents.
    pub fn replaces_keyframes(self) -> bool {
        !matches!(self, KeyframeConditioning::None)
    }
}

/// What the network's output is (docs/method.md §4.9, `model.prediction`): the velocity of (R4), as in the paper, or
/// the clean latents Ẑ, turned into the velocity (Ẑ − X_τ) / (1 − τ) before (R5) and (R6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Prediction {
    /// v_θ directly (the paper).
    #[default]
    Velocity,
    /// The clean trajectory latents (x-prediction; not in the paper).
    Data,
}

/// What the flow generates (docs/method.md §4.10, `model.anchor`): the trajectory latents themselves, as in the paper,
/// or their residual from the keyframes' latent interpolation A, scaled: X₁ = (Z − A)/s, Ẑ = A + s X₁.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Anchor {
    /// X₁ = Z (the paper).
    #[default]
    None,
    /// X₁ = (Z − A)/scale with A the keyframes' interpolation along the frames ([`crate::anchor::keyframe_lerp`]);
    /// `scale` > 0 is about the residual's standard deviation in standardized units, so that X₁ is near unit scale.
    KeyframeLerp {
        /// s.
        scale: f64,
    },
}

/// Size of the MMDiT: the `[model]` table of `configs/rf/*.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MmditConfig {
    /// Model width W (512 in the paper).
    pub width: usize,
    /// Number of MMDiT blocks (12).
    pub blocks: usize,
    /// Attention heads H; the head width is W / H (8 × 64).
    pub heads: usize,
    /// Frames T per window (16); slots = T + 1.
    pub frames: usize,
    /// Latent channels C per slot (12).
    pub channels: usize,
    /// Width D_txt of the text encoder's token states (768 for CLIP ViT-L/14).
    pub text_dim: usize,
    /// How keyframes are given to the network (`kf_mode` in run folders written before the rename).
    #[serde(alias = "kf_mode")]
    pub conditioning: KeyframeConditioning,
    /// What the output is: velocity (the paper) or clean latents (docs/method.md §4.9). Run folders written before
    /// the key existed predict velocity.
    #[serde(default)]
    pub prediction: Prediction,
    /// What the flow generates: the latents (the paper) or their residual from the keyframe interpolation
    /// (docs/method.md §4.10; needs `conditioning = "input_mask"`). Run folders written before the key existed have
    /// none.
    #[serde(default)]
    pub anchor: Anchor,
    /// Which scene features the network reads (docs/method.md §4.12; off in the paper presets and in run folders
    /// written before the key existed).
    #[serde(default)]
    pub scene: SceneConditioning,
}

impl MmditConfig {
    /// The paper's size (docs/method.md §4.3) for a given keyframe mode and text width.
    pub fn paper(conditioning: KeyframeConditioning, text_dim: usize) -> Self {
        Self {
            width: 512,
            blocks: 12,
            heads: 8,
            frames: 16,
            channels: 12,
            text_dim,
            conditioning,
            prediction: Prediction::Velocity,
            anchor: Anchor::None,
            scene: SceneConditioning::default(),
        }
    }

    /// A few-thousand-parameter model for unit tests.
    pub fn tiny() -> Self {
        Self {
            width: 32,
            blocks: 2,
            heads: 2,
            frames: 4,
            channels: 3,
            text_dim: 8,
            conditioning: KeyframeConditioning::InputMask,
            prediction: Prediction::Velocity,
            anchor: Anchor::None,
            scene: SceneConditioning::default(),
        }
    }

    /// Input channels per token: (T+1)(C+1) with mask channels, (T+1)·C without (docs/method.md §4.1).
    pub fn in_channels(&self) -> usize {
        let per_slot = self.channels + usize::from(self.conditioning.has_mask_channels());
        (self.frames + 1) * per_slot
    }

    /// Output channels per token: T·C velocities of slots 1..T.
    pub fn out_channels(&self) -> usize {
        self.frames * self.channels
    }

    /// Checks the sizes; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        for (name, value) in [
            ("width", self.width),
            ("blocks", self.blocks),
            ("heads", self.heads),
            ("frames", self.frames),
            ("channels", self.channels),
            ("text_dim", self.text_dim),
        ] {
            if value == 0 {
                return Err(format!("model.{name} must be positive, got 0"));
            }
        }
        if !self.width.is_multiple_of(self.heads) {
            return Err(format!(
                "model.width ({}) must be a multiple of model.heads ({})",
                self.width, self.heads
            ));
        }
        if let Anchor::KeyframeLerp { scale } = self.anchor {
            if !(scale > 0.0 && scale.is_finite()) {
                return Err(format!(
                    "model.anchor.keyframe_lerp.scale {scale} must be finite and positive"
                ));
            }
            if self.conditioning != KeyframeConditioning::InputMask {
                return Err(format!(
                    "model.anchor = keyframe_lerp needs model.conditioning = \"input_mask\" (the anchor is built from \
                     the clean keyframes), got {:?}",
                    self.conditioning
                ));
            }
        }
        self.scene.validate()?;
        if self.scene.local && !self.conditioning.has_mask_channels() {
            return Err(format!(
                "model.scene.local reads the scene at keyframes, and model.conditioning = {:?} trains without any: \
                 use model.scene.global only",
                self.conditioning
            ));
        }
        crate::summary::check_param_estimate(
            "model.width, blocks, frames, channels and text_dim",
            self.param_estimate(),
        )
    }

    /// Builds the network: AAM initialisation (N(0, (0.25/√W)²) for attention, MLP and time MLP, PyTorch-default
    /// adaLN and input projections, zero-initialised output projection).
    ///
    /// # Panics
    /// If [`MmditConfig::validate`] fails (a programming error: configs are validated when loaded).
    pub fn init(&self, device: &Device) -> Mmdit {
        if let Err(msg) = self.validate() {
            panic!("invalid MmditConfig: {msg}");
        }
        let w = self.width;
        let lin = |d_in: usize, d_out: usize, init: LinearInit| init.linear(d_in, d_out, w, device);
        let (aam, default) = (LinearInit::Aam, LinearInit::TorchDefault);
        let blocks = (0..self.blocks)
            .map(|_| MmditBlock {
                ada_motion: lin(w, 6 * w, default),
                ada_text: lin(w, 6 * w, default),
                qkv: lin(w, 3 * w, aam),
                proj: lin(w, w, aam),
                norm2_motion: LayerNormConfig::new(w).init(device),
                norm2_text: LayerNormConfig::new(w).init(device),
                fc1: lin(w, 4 * w, aam),
                fc2: lin(4 * w, w, aam),
                heads: self.heads,
            })
            .collect();
        Mmdit {
            input_proj: lin(self.in_channels(), w, default),
            input_norm: LayerNormConfig::new(w).init(device),
            text_proj: lin(self.text_dim, w, default),
            text_norm: LayerNormConfig::new(w).init(device),
            scene_global: self.scene.init_global(w, device),
            scene_local: self.scene.init_local(w, self.frames, device),
            time: TimestepEmbedder {
                fc1: lin(2 * TIME_FREQS, 4 * w, aam),
                fc2: lin(4 * w, w, aam),
            },
            blocks,
            final_norm: LayerNormConfig::new(w).init(device),
            output_proj: lin(w, self.out_channels(), LinearInit::Zero),
            in_channels: self.in_channels(),
            text_dim: self.text_dim,
            prediction: self.prediction,
            anchor: self.anchor,
            scene: self.scene.clone(),
        }
    }
}

/// Initialisation of one Linear layer (AAM code, docs/method.md §4.3).
#[derive(Clone, Copy)]
enum LinearInit {
    /// PyTorch's default `U(±1/√fan_in)` for weight and bias (burn's default Linear init is the same).
    TorchDefault,
    /// Weight N(0, (0.25/√W)²), bias 0.
    Aam,
    /// Weight and bias 0 (output projection).
    Zero,
}

impl LinearInit {
    fn linear(self, d_in: usize, d_out: usize, width: usize, device: &Device) -> Linear {
        let cfg = LinearConfig::new(d_in, d_out);
        match self {
            LinearInit::TorchDefault => cfg.init(device),
            LinearInit::Zero => cfg.with_initializer(Initializer::Zeros).init(device),
            LinearInit::Aam => {
                let std = 0.25 / (width as f64).sqrt();
                let mut layer = cfg
                    .with_initializer(Initializer::Normal { mean: 0.0, std })
                    .init(device);
                layer.bias = Some(Initializer::Zeros.init([d_out], device));
                layer
            }
        }
    }
}
