//! Keyframe-conditioned rectified-flow backbone: the MMDiT of docs/method.md §4.1 and §4.3 (CompletionAny4D P-Eq. 9 and
//! 14, on AnimateAnyMesh's "40m" CogX-style MMDiT), plus the slot-major token layout of (R3).
//!
//! Reading order as in DiT's `models.py`: helpers → timestep embedder → block (`pre_attention` / joint attention /
//! `post_attention`, as in SD3's `mmdit.py`) → model. One token per FPS point; the 16 frames live in the channels.

use crate::gelu::gelu;
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::activation::silu;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use serde::{Deserialize, Serialize};

/// Frequencies of the timestep sinusoid (docs/method.md §4.3): the embedding has `2 · TIME_FREQS` values `[cos ‖ sin]`.
pub const TIME_FREQS: usize = 256;
/// Epsilon of the affine-free LayerNorm in front of the joint attention (AAM `LN0`).
const PRE_NORM_EPS: f64 = 1e-6;

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
        crate::summary::check_param_estimate(
            "model.width, blocks, frames, channels and text_dim",
            self.param_estimate(),
        )
    }

    /// An upper estimate of the parameter count, computed without allocating: per block two streams of qkv, output,
    /// MLP (4W) and adaLN (6W) projections (≈ 36 W²), plus input, text, time and output projections.
    pub fn param_estimate(&self) -> u128 {
        let (w, b) = (self.width as u128, self.blocks as u128);
        let io = (self.in_channels() as u128 + self.out_channels() as u128 + self.text_dim as u128 + 1) * w;
        let time = 512 * 4 * w + 4 * w * w;
        b * 40 * w * w + io + time
    }

    /// A rough count of the bytes one training micro-batch keeps for the backward pass (f32), computed without
    /// allocating: per block and token about 16 W values (norms, qkv, attention output, projections, the 4W MLP
    /// twice, residuals) and per block and clip two `heads × S × S` attention maps, S = `tokens + text_len`.
    pub fn activation_bytes(&self, micro_batch: usize, tokens: usize, text_len: usize) -> u128 {
        let (b, s) = (micro_batch as u128, (tokens + text_len) as u128);
        let per_block = b * (16 * self.width as u128 * s + 2 * self.heads as u128 * s * s);
        4 * self.blocks as u128 * per_block
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
        }
    }
}

/// Analytic model FLOPs of one pass of a network for one sample (multiply and add count as two), split into
/// matrix products with weights and attention. See [`MmditConfig::forward_flops`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlopCount {
    /// Σ 2·in·out over every Linear application (once per token it acts on, or once per sample).
    pub linear: u64,
    /// Σ 2·2·L_q·L_k·W over the attention layers (QKᵀ and the weighted sum of V, all heads).
    pub attention: u64,
}

impl FlopCount {
    /// FLOPs of the forward pass.
    pub fn forward(self) -> u64 {
        self.linear + self.attention
    }

    /// FLOPs of a training step (forward + backward): 3 × forward, the backward pass computing gradients with
    /// respect to both the activations and the weights of every product.
    pub fn training_step(self) -> u64 {
        3 * self.forward()
    }
}

impl std::ops::Add for FlopCount {
    type Output = FlopCount;

    fn add(self, other: FlopCount) -> FlopCount {
        FlopCount {
            linear: self.linear + other.linear,
            attention: self.attention + other.attention,
        }
    }
}

impl MmditConfig {
    /// Model FLOPs of one forward pass of [`Mmdit::forward`] for one sample with P = `tokens` motion tokens and
    /// L = `text_len` text tokens, joint sequence S = P + L, width W, B blocks:
    ///
    /// ```text
    /// linear    = 2·[ P·in_channels·W + L·text_dim·W + P·W·out_channels      input, text, output projections
    ///               + 2·TIME_FREQS·4W + 4W·W                               timestep MLP (once per sample)
    ///               + B·( 2·W·6W                                           adaLN of both streams (per sample)
    ///                   + S·(3W² + W² + 4W² + 4W²) ) ]                     qkv, proj, fc1, fc2 on all S tokens
    /// attention = B · 2·2·S²·W                                             QKᵀ and softmax·V, all heads
    /// ```
    ///
    /// Biases, LayerNorms, activations, the softmax, adaLN modulation and residuals are not counted (each is
    /// O(S·W) against O(S·W²)). A training step is [`FlopCount::training_step`] = 3 × forward. The text encoder
    /// that feeds `text` is not included.
    pub fn forward_flops(&self, tokens: usize, text_len: usize) -> FlopCount {
        let [p, l, s, w] = [tokens, text_len, tokens + text_len, self.width].map(|x| x as u64);
        let [blocks, d_in, d_out, d_txt, freqs] = [
            self.blocks,
            self.in_channels(),
            self.out_channels(),
            self.text_dim,
            TIME_FREQS,
        ]
        .map(|x| x as u64);
        let projections = p * d_in * w + l * d_txt * w + p * w * d_out;
        let time = 2 * freqs * 4 * w + 4 * w * w;
        let per_block = 2 * w * 6 * w + s * (3 * w * w + w * w + 4 * w * w + 4 * w * w);
        FlopCount {
            linear: 2 * (projections + time + blocks * per_block),
            attention: blocks * 2 * 2 * s * s * w,
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

// ---------------------------------------------------------------------------------------------------------------
// Helpers

/// LayerNorm over the last axis without affine parameters (AAM `LN0`, eps 1e-6).
fn plain_layer_norm(x: Tensor<3>) -> Tensor<3> {
    let mean = x.clone().mean_dim(2);
    let centred = x - mean;
    let var = centred.clone().square().mean_dim(2);
    centred / var.add_scalar(PRE_NORM_EPS).sqrt()
}

/// `x · (1 + scale) + shift` with per-sample `[B, 1, W]` modulation.
fn modulate(x: Tensor<3>, shift: Tensor<3>, scale: Tensor<3>) -> Tensor<3> {
    x.clone() * scale + x + shift
}

/// Sinusoid of the raw flow time: `f_i = exp(−ln(10⁴)·i/256)`, output `[cos(τ f) ‖ sin(τ f)]` (docs/method.md §4.3).
///
/// # Shapes
/// - tau: `[B]` (τ ∈ [0, 1], τ = 0 noise, τ = 1 data)
/// - output: `[B, 2·TIME_FREQS]`
pub fn timestep_sinusoid(tau: Tensor<1>) -> Tensor<2> {
    let device = tau.device();
    let freqs = Tensor::<1, Int>::arange(0..TIME_FREQS as i64, &device)
        .float()
        .mul_scalar(-(10_000f64.ln()) / TIME_FREQS as f64)
        .exp();
    let angles = tau.unsqueeze_dim::<2>(1) * freqs.unsqueeze_dim::<2>(0);
    Tensor::cat(vec![angles.clone().cos(), angles.sin()], 1)
}

// ---------------------------------------------------------------------------------------------------------------
// Token layout (docs/method.md §4.1, (R3))

/// Keyframe replacement `m ⊙ z_key + (1 − m) ⊙ x` — the first half of (R3), and of (R7) when `z_key` is noised.
///
/// # Shapes
/// - x, z_key: `[B, P, T, C]` (token-major: the layout of the network's output)
/// - mask: `[B, T]`, 1 = observed keyframe
/// - output: `[B, P, T, C]`
pub fn replace_keyframes(x: Tensor<4>, z_key: Tensor<4>, mask: Tensor<2>) -> Tensor<4> {
    let [b, t] = mask.dims();
    let m = mask.reshape([b, 1, t, 1]);
    // (R3) Ẑ = m ⊙ Z_key + (1 − m) ⊙ X
    z_key * m.clone() + x * m.neg().add_scalar(1.0)
}

/// Interleaves the slots into the network input: slot-major `[z_s(C) ‖ m̂_s(1)]`, s = 0..T, with m̂ = [0; m]
/// (mask channels only for [`KeyframeConditioning::has_mask_channels`]). The second half of (R3).
///
/// # Shapes
/// - z0: `[B, P, C]` shape latent (slot 0)
/// - state: `[B, P, T, C]` trajectory slots 1..T (already replaced where wanted)
/// - mask: `[B, T]` mask channel values, 1 = observed
/// - output: `[B, P, (T+1)(C+1)]` or `[B, P, (T+1)·C]`
pub fn assemble_input(
    z0: Tensor<3>,
    state: Tensor<4>,
    mask: Tensor<2>,
    conditioning: KeyframeConditioning,
) -> Tensor<3> {
    let [b, p, t, c] = state.dims();
    let slots = Tensor::cat(vec![z0.unsqueeze_dim::<4>(2), state], 2); // [B, P, T+1, C]
    if !conditioning.has_mask_channels() {
        return slots.reshape([b, p, (t + 1) * c]);
    }
    let device = mask.device();
    let m_hat = Tensor::cat(vec![Tensor::<2>::zeros([b, 1], &device), mask], 1); // m̂ = [0; m]
    let m_hat = m_hat.reshape([b, 1, t + 1, 1]).expand([b, p, t + 1, 1]);
    Tensor::cat(vec![slots, m_hat], 3).reshape([b, p, (t + 1) * (c + 1)])
}

/// The network input of (R3): keyframe slots take `z_key` where `mask` = 1 (not for [`KeyframeConditioning::None`]), slot 0 takes
/// the clean shape latent, and mask channels m̂ = [0; m] follow each slot when the mode has them.
///
/// # Shapes
/// - z0: `[B, P, C]`; x, z_key: `[B, P, T, C]`; mask: `[B, T]` (1 = observed)
/// - output: `[B, P, in_channels]` with in_channels = (T+1)(C+1) or (T+1)·C
pub fn build_input(
    z0: Tensor<3>,
    x: Tensor<4>,
    mask: Tensor<2>,
    z_key: Tensor<4>,
    conditioning: KeyframeConditioning,
) -> Tensor<3> {
    let state = if conditioning.replaces_keyframes() {
        replace_keyframes(x, z_key, mask.clone())
    } else {
        x
    };
    assemble_input(z0, state, mask, conditioning)
}

/// Inverse of the output layout: slot-major velocities of slots 1..T.
///
/// # Shapes
/// - v: `[B, P, T·C]`
/// - output: `[B, P, T, C]`
pub fn split_output(v: Tensor<3>, frames: usize) -> Tensor<4> {
    let [b, p, tc] = v.dims();
    assert!(
        tc % frames == 0,
        "split_output: {tc} channels are not a multiple of {frames} frames"
    );
    v.reshape([b, p, frames, tc / frames])
}

/// Flattens `[B, P, T, C]` into the output layout `[B, P, T·C]` (inverse of [`split_output`]).
pub fn merge_slots(x: Tensor<4>) -> Tensor<3> {
    let [b, p, t, c] = x.dims();
    x.reshape([b, p, t * c])
}

// ---------------------------------------------------------------------------------------------------------------
// Timestep embedder

/// Sinusoid of τ → Linear(512 → 4W) → GELU → Linear(4W → W) (docs/method.md §4.3; no SiLU in front).
#[derive(Module, Debug)]
pub struct TimestepEmbedder {
    fc1: Linear,
    fc2: Linear,
}

impl TimestepEmbedder {
    /// # Shapes
    /// - tau: `[B]` raw flow time (τ, not 1 − τ)
    /// - output: `[B, W]`
    pub fn forward(&self, tau: Tensor<1>) -> Tensor<2> {
        self.fc2.forward(gelu(self.fc1.forward(timestep_sinusoid(tau))))
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Block

/// The six adaLN vectors of one modality, each `[B, 1, W]`.
pub struct Modulation {
    shift1: Tensor<3>,
    scale1: Tensor<3>,
    gate1: Tensor<3>,
    shift2: Tensor<3>,
    scale2: Tensor<3>,
    gate2: Tensor<3>,
}

impl Modulation {
    fn from_linear(ada: &Linear, temb_act: Tensor<2>) -> Self {
        let mut parts = ada.forward(temb_act).unsqueeze_dim::<3>(1).chunk(6, 2).into_iter();
        let mut next = || parts.next().expect("six adaLN chunks");
        Self {
            shift1: next(),
            scale1: next(),
            gate1: next(),
            shift2: next(),
            scale2: next(),
            gate2: next(),
        }
    }
}

/// One MMDiT block (CogX style): per-modality adaLN, joint attention and MLP with weights shared by both streams.
#[derive(Module, Debug)]
pub struct MmditBlock {
    ada_motion: Linear,
    ada_text: Linear,
    qkv: Linear,
    proj: Linear,
    norm2_motion: LayerNorm,
    norm2_text: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
}

impl MmditBlock {
    /// adaLN of both streams and their concatenation for the joint attention.
    ///
    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, temb_act `[B, W]` (SiLU already applied)
    /// - output: joint `[B, P+L, W]` and the two modulations
    pub fn pre_attention(
        &self,
        motion: Tensor<3>,
        text: Tensor<3>,
        temb_act: Tensor<2>,
    ) -> (Tensor<3>, Modulation, Modulation) {
        let mod_m = Modulation::from_linear(&self.ada_motion, temb_act.clone());
        let mod_t = Modulation::from_linear(&self.ada_text, temb_act);
        let nm = modulate(plain_layer_norm(motion), mod_m.shift1.clone(), mod_m.scale1.clone());
        let nt = modulate(plain_layer_norm(text), mod_t.shift1.clone(), mod_t.scale1.clone());
        (Tensor::cat(vec![nm, nt], 1), mod_m, mod_t)
    }

    /// Joint multi-head self-attention over the P + L tokens, no mask, no positional encoding. The qkv output is
    /// head-major with `q | k | v` inside each head (AAM memory layout, so AAM weights port without permutation).
    ///
    /// # Shapes
    /// - joint: `[B, S, W]` with S = P + L; output `[B, S, W]`
    pub fn joint_attention(&self, joint: Tensor<3>) -> Tensor<3> {
        let [b, s, w] = joint.dims();
        let h = self.heads;
        let hd = w / h;
        let qkv = self.qkv.forward(joint).reshape([b, s, h, 3 * hd]).swap_dims(1, 2); // [B, H, S, 3·hd]
        let mut parts = qkv.chunk(3, 3).into_iter();
        let (q, k, v) = (parts.next().unwrap(), parts.next().unwrap(), parts.next().unwrap());
        let options = AttentionModuleOptions {
            scale: None,
            softcap: None,
            is_causal: false,
        };
        let out = attention(q, k, v, None, None, options); // [B, H, S, hd]
        self.proj.forward(out.swap_dims(1, 2).reshape([b, s, w]))
    }

    /// Gated residuals of the attention output, then adaLN + shared MLP + gated residual on each stream.
    ///
    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, attn `[B, P+L, W]`; outputs `[B, P, W]`, `[B, L, W]`
    pub fn post_attention(
        &self,
        motion: Tensor<3>,
        text: Tensor<3>,
        attn: Tensor<3>,
        mod_m: Modulation,
        mod_t: Modulation,
    ) -> (Tensor<3>, Tensor<3>) {
        let [_, p, _] = motion.dims();
        let [_, l, _] = text.dims();
        let am = attn.clone().narrow(1, 0, p);
        let at = attn.narrow(1, p, l);
        let motion = motion + mod_m.gate1 * am;
        let text = text + mod_t.gate1 * at;
        let mm = modulate(self.norm2_motion.forward(motion.clone()), mod_m.shift2, mod_m.scale2);
        let mt = modulate(self.norm2_text.forward(text.clone()), mod_t.shift2, mod_t.scale2);
        let f = self.fc2.forward(gelu(self.fc1.forward(Tensor::cat(vec![mm, mt], 1))));
        let fm = f.clone().narrow(1, 0, p);
        let ft = f.narrow(1, p, l);
        (motion + mod_m.gate2 * fm, text + mod_t.gate2 * ft)
    }

    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, temb_act `[B, W]`; outputs `[B, P, W]`, `[B, L, W]`
    pub fn forward(&self, motion: Tensor<3>, text: Tensor<3>, temb_act: Tensor<2>) -> (Tensor<3>, Tensor<3>) {
        let (joint, mod_m, mod_t) = self.pre_attention(motion.clone(), text.clone(), temb_act);
        let attn = self.joint_attention(joint);
        self.post_attention(motion, text, attn, mod_m, mod_t)
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Model

/// The keyframe-conditioned rectified-flow MMDiT: v_θ = MMDiT(input, text, τ) (R4).
#[derive(Module, Debug)]
pub struct Mmdit {
    input_proj: Linear,
    input_norm: LayerNorm,
    text_proj: Linear,
    text_norm: LayerNorm,
    time: TimestepEmbedder,
    blocks: Vec<MmditBlock>,
    final_norm: LayerNorm,
    output_proj: Linear,
    in_channels: usize,
    text_dim: usize,
    #[module(skip)]
    prediction: Prediction,
    #[module(skip)]
    anchor: Anchor,
}

impl Mmdit {
    /// Velocity of slots 1..T (R4).
    ///
    /// # Shapes
    /// - input: `[B, P, in_channels]` from [`build_input`]
    /// - text: `[B, L, D_txt]` token states of the text encoder
    /// - keep_txt: `[B]`, 1 = keep the text, 0 = dropped (CFG); multiplies the projected text before its LayerNorm
    /// - tau: `[B]` flow time, 0 = noise, 1 = data
    /// - output: `[B, P, T·C]`
    ///
    /// # Panics
    /// If the channel axes do not match the config (checked with a message naming the tensor).
    pub fn forward(&self, input: Tensor<3>, text: Tensor<3>, keep_txt: Tensor<1>, tau: Tensor<1>) -> Tensor<3> {
        let [b, _, in_ch] = input.dims();
        let [bt, _, d_txt] = text.dims();
        assert_eq!(
            in_ch, self.in_channels,
            "Mmdit::forward: input has {in_ch} channels, model expects {}",
            self.in_channels
        );
        assert_eq!(
            d_txt, self.text_dim,
            "Mmdit::forward: text has width {d_txt}, model expects {}",
            self.text_dim
        );
        assert_eq!(bt, b, "Mmdit::forward: text batch {bt} differs from input batch {b}");
        let motion = self.input_norm.forward(self.input_proj.forward(input));
        let keep = keep_txt.reshape([b, 1, 1]);
        let text = self.text_norm.forward(self.text_proj.forward(text) * keep);
        let temb_act = silu(self.time.forward(tau));
        let (mut motion, mut text) = (motion, text);
        for block in &self.blocks {
            (motion, text) = block.forward(motion, text, temb_act.clone());
        }
        self.output_proj.forward(self.final_norm.forward(motion))
    }

    /// The timestep embedder (exposed for the τ-direction test of docs/method.md §1.4).
    pub fn timestep_embedder(&self) -> &TimestepEmbedder {
        &self.time
    }

    /// Input channels this network was built for.
    pub fn in_channels(&self) -> usize {
        self.in_channels
    }

    /// Width of the text states this network reads.
    pub fn text_dim(&self) -> usize {
        self.text_dim
    }

    /// What [`Mmdit::forward`] outputs: velocities or clean latents (docs/method.md §4.9).
    pub fn prediction(&self) -> Prediction {
        self.prediction
    }

    /// What the flow generates: latents or their residual from the keyframe interpolation (docs/method.md §4.10).
    pub fn anchor(&self) -> Anchor {
        self.anchor
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn activation_estimate_grows_with_batch_width_and_tokens() {
        let cfg = MmditConfig {
            width: 128,
            blocks: 4,
            heads: 4,
            ..MmditConfig::paper(KeyframeConditioning::InputMask, 128)
        };
        let one = cfg.activation_bytes(1, 128, 16);
        // 4 blocks × (16·128·144 + 2·4·144²) f32 values.
        assert_eq!(one, 4 * 4 * (16 * 128 * 144 + 2 * 4 * 144 * 144));
        assert_eq!(cfg.activation_bytes(32, 128, 16), 32 * one);
        assert!(cfg.activation_bytes(1, 512, 16) > 4 * one);
    }

    use super::*;
    use crate::summary::named_params;

    /// 2 × Σ (weight-matrix size × the number of times the layer is applied per sample), read from the module's
    /// own 2-D parameters: motion-only layers act on P tokens, the text projection on L, the shared block
    /// layers on S = P + L, the timestep MLP and adaLN once per sample. An unknown 2-D parameter fails the test,
    /// so a Linear added to the network without updating [`MmditConfig::forward_flops`] is caught.
    fn linear_flops_of_weights(model: &Mmdit, tokens: u64, text_len: u64) -> u64 {
        let mut flops = 0;
        for p in named_params(model).into_iter().filter(|p| p.shape.len() == 2) {
            let layer = p.path.iter().rev().nth(1).map_or("", String::as_str);
            let applications = match (p.path[0].as_str(), layer) {
                ("input_proj" | "output_proj", _) => tokens,
                ("text_proj", _) => text_len,
                ("time", _) | ("blocks", "ada_motion" | "ada_text") => 1,
                ("blocks", "qkv" | "proj" | "fc1" | "fc2") => tokens + text_len,
                _ => panic!("2-D parameter {} has no FLOP rule", p.path.join(".")),
            };
            flops += 2 * p.numel() as u64 * applications;
        }
        flops
    }

    #[test]
    fn linear_flops_match_the_weights_of_the_initialised_module() {
        let device = Device::flex();
        let mut other = MmditConfig::tiny();
        (other.conditioning, other.text_dim, other.blocks, other.width) = (KeyframeConditioning::None, 12, 3, 24);
        for (cfg, tokens, text_len) in [(MmditConfig::tiny(), 7, 3), (other, 5, 11)] {
            let weights = linear_flops_of_weights(&cfg.init(&device), tokens, text_len);
            let counted = cfg.forward_flops(tokens as usize, text_len as usize);
            assert_eq!(counted.linear, weights, "{cfg:?}");
        }
    }

    #[test]
    fn attention_flops_are_quadratic_in_the_joint_sequence_and_training_is_three_passes() {
        // Tiny: W 32, 2 blocks, S = 5 + 3 = 8: 2 blocks × (QKᵀ: 2·8·8·32 + softmax·V: 2·8·8·32) = 16384, whatever
        // the head count.
        let cfg = MmditConfig::tiny();
        let flops = cfg.forward_flops(5, 3);
        assert_eq!(flops.attention, 16_384);
        let mut more_heads = cfg.clone();
        more_heads.heads = 8;
        assert_eq!(more_heads.forward_flops(5, 3), flops);
        assert_eq!(cfg.forward_flops(13, 3).attention, 16_384 * 4);
        assert_eq!(flops.training_step(), 3 * (flops.linear + flops.attention));
    }

    use burn::tensor::Distribution;

    /// Replaces all-zero float parameters (zero-initialised adaLN and output projections) with N(0, 0.3²), so the
    /// output depends on τ.
    struct Wake;

    impl burn::module::ModuleMapper for Wake {
        fn map_float<const D: usize>(
            &mut self,
            param: burn::module::Param<Tensor<D>>,
        ) -> burn::module::Param<Tensor<D>> {
            param.map(|t| {
                let peak = t.clone().abs().max().into_scalar::<f32>();
                if peak == 0.0 {
                    t.random_like(Distribution::Normal(0.0, 0.3))
                } else {
                    t
                }
            })
        }
    }

    /// docs/method.md §1.4 (4) at the network: `forward(…, τ)` embeds τ itself. The reference below runs the same
    /// layers with the embedding of τ written out; a flip to 1 − τ anywhere inside `forward` makes the two differ
    /// (the output is checked to depend on τ, so the comparison can fail).
    #[test]
    fn forward_embeds_tau_not_one_minus_tau() {
        let device = Device::flex();
        let cfg = MmditConfig::tiny();
        let model = cfg.init(&device).map(&mut Wake);
        let (b, p, l) = (2, 5, 3);
        let input = Tensor::<3>::random([b, p, cfg.in_channels()], Distribution::Normal(0.0, 1.0), &device);
        let text = Tensor::<3>::random([b, l, cfg.text_dim], Distribution::Normal(0.0, 1.0), &device);
        let keep = Tensor::<1>::ones([b], &device);
        let reference = |tau: f32| {
            let tau = Tensor::<1>::full([b], tau, &device);
            let motion = model.input_norm.forward(model.input_proj.forward(input.clone()));
            let text = model.text_norm.forward(model.text_proj.forward(text.clone()));
            let temb = silu(
                model
                    .time
                    .fc2
                    .forward(gelu(model.time.fc1.forward(timestep_sinusoid(tau)))),
            );
            let (mut m, mut t) = (motion, text);
            for block in &model.blocks {
                (m, t) = block.forward(m, t, temb.clone());
            }
            model.output_proj.forward(model.final_norm.forward(m))
        };
        let run = |tau: f32| {
            model.forward(
                input.clone(),
                text.clone(),
                keep.clone(),
                Tensor::full([b], tau, &device),
            )
        };
        let gap = |a: Tensor<3>, b: Tensor<3>| (a - b).abs().max().into_scalar::<f32>();
        for tau in [0.1f32, 0.3, 0.8] {
            assert!(
                gap(run(tau), reference(tau)) < 1e-5,
                "forward(τ = {tau}) is not the network at τ"
            );
            assert!(
                gap(reference(tau), reference(1.0 - tau)) > 1e-3,
                "the output does not depend on τ, so the check above could not fail"
            );
        }
    }
}
