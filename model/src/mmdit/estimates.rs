//! What an MMDiT costs, computed from its configuration without allocating: parameters, activation memory of a
//! training micro-batch, and model FLOPs (docs/method.md §4.3).

use super::{MmditConfig, TIME_FREQS};

impl MmditConfig {
    /// An upper estimate of the parameter count, computed without allocating: per block two streams of qkv, output,
    /// MLP (4W) and adaLN (6W) projections (≈ 36 W²), plus input, text, time and output projections.
    pub fn param_estimate(&self) -> u128 {
        let (w, b) = (self.width as u128, self.blocks as u128);
        let io = (self.in_channels() as u128 + self.out_channels() as u128 + self.text_dim as u128 + 1) * w;
        let time = 512 * 4 * w + 4 * w * w;
        b * 40 * w * w + io + time + self.scene.param_count(self.width, self.frames) as u128
    }

    /// A rough count of the bytes one training micro-batch keeps for the backward pass (f32), computed without
    /// allocating: per block and token about 16 W values (norms, qkv, attention output, projections, the 4W MLP
    /// twice, residuals) and per block and clip two `heads × S × S` attention maps, S = `tokens + text_len` (+ the
    /// scene's context tokens, docs/method.md §4.12).
    pub fn activation_bytes(&self, micro_batch: usize, tokens: usize, text_len: usize) -> u128 {
        let (b, s) = (micro_batch as u128, (tokens + text_len + self.scene.tokens()) as u128);
        let per_block = b * (16 * self.width as u128 * s + 2 * self.heads as u128 * s * s);
        4 * self.blocks as u128 * per_block
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
    /// With scene parts (docs/method.md §4.12) the N_s grid tokens join the text stream (L + N_s in S and in the
    /// blocks) and add N_s·patch³·W for their projection (S3); the keyframe offsets add P·(4T·W + W²) (S4).
    ///
    /// Biases, LayerNorms, activations, the softmax, adaLN modulation and residuals are not counted (each is
    /// O(S·W) against O(S·W²)). A training step is [`FlopCount::training_step`] = 3 × forward. The text encoder
    /// that feeds `text` is not included.
    pub fn forward_flops(&self, tokens: usize, text_len: usize) -> FlopCount {
        let scene_tokens = self.scene.tokens();
        let context = text_len + scene_tokens;
        let [p, l, s, w] = [tokens, text_len, tokens + context, self.width].map(|x| x as u64);
        let [blocks, d_in, d_out, d_txt, freqs] = [
            self.blocks,
            self.in_channels(),
            self.out_channels(),
            self.text_dim,
            TIME_FREQS,
        ]
        .map(|x| x as u64);
        let mut projections = p * d_in * w + l * d_txt * w + p * w * d_out;
        if self.scene.global {
            projections += scene_tokens as u64 * self.scene.patch.pow(3) as u64 * w;
        }
        if self.scene.local {
            projections += p * (super::LOCAL_CHANNELS * self.frames) as u64 * w + p * w * w;
        }
        let time = 2 * freqs * 4 * w + 4 * w * w;
        let per_block = 2 * w * 6 * w + s * (3 * w * w + w * w + 4 * w * w + 4 * w * w);
        FlopCount {
            linear: 2 * (projections + time + blocks * per_block),
            attention: blocks * 2 * 2 * s * s * w,
        }
    }
}
