//! Per-frame encoder/decoder of the BD-LSTM baseline: the trait both variants implement and the latent
//! adaptation's dense codec on standardised trajectory latents (ours; the original uses mesh convolutions,
//! `mesh_conv.rs`).

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::activation::tanh;

/// Clamp of the encoder's log-variance, as in the VAE bottleneck (keeps exp finite).
pub const LOGVAR_MIN: f64 = -30.0;
/// See [`LOGVAR_MIN`].
pub const LOGVAR_MAX: f64 = 20.0;

/// What a BD-LSTM chain needs from a frame representation: an encoder to the LSTM's input (a Gaussian posterior,
/// for the KL of (B3)) and a decoder from the LSTM's output to the frame change ΔX (the Conv / tCnv pair of Qiao et al., Eq. 2).
pub trait FrameCodec: Module {
    /// Extra input the codec needs besides the frames (`()` for latents, the mesh graph for ACAP features).
    type Context;

    /// Latent width: the encoder's output, the LSTM's input and hidden width, the decoder's input.
    fn latent_width(&self) -> usize;

    /// Posterior mean and clamped log-variance of each frame.
    ///
    /// # Shapes
    /// - `x`: `[B, K, C]` one frame (K tokens or vertices, C channels) → (`[B, Z]`, `[B, Z]`)
    fn encode(&self, x: Tensor<3>, ctx: &Self::Context) -> (Tensor<2>, Tensor<2>);

    /// The frame change ΔX predicted from the LSTM's output.
    ///
    /// # Shapes
    /// - `h`: `[B, Z]` → `[B, K, C]`
    fn decode(&self, h: Tensor<2>, ctx: &Self::Context) -> Tensor<3>;
}

/// Configuration of [`LatentCodec`] (defaults: the paper-scale adaptation, P = 512 tokens of C = 12, width 16, latent 128).
#[derive(Config, Debug)]
pub struct LatentCodecConfig {
    /// Tokens per frame P (FPS order).
    #[config(default = 512)]
    pub tokens: usize,
    /// Channels per token C (the VAE's trajectory latent).
    #[config(default = 12)]
    pub channels: usize,
    /// Per-token width after the first layer.
    #[config(default = 16)]
    pub token_width: usize,
    /// Latent width Z (LSTM input and hidden width).
    #[config(default = 128)]
    pub latent: usize,
}

impl LatentCodecConfig {
    /// A small configuration for unit tests (P 6, C 4, width 3, latent 8).
    pub fn tiny() -> Self {
        Self::new()
            .with_tokens(6)
            .with_channels(4)
            .with_token_width(3)
            .with_latent(8)
    }

    /// Builds the codec on `device`.
    pub fn init(&self, device: &Device) -> LatentCodec {
        let flat = self.tokens * self.token_width;
        LatentCodec {
            token_in: LinearConfig::new(self.channels, self.token_width).init(device),
            to_mu: LinearConfig::new(flat, self.latent).init(device),
            to_logvar: LinearConfig::new(flat, self.latent).init(device),
            from_latent: LinearConfig::new(self.latent, flat).init(device),
            token_out: LinearConfig::new(self.token_width, self.channels).init(device),
            tokens: self.tokens,
            token_width: self.token_width,
            latent: self.latent,
        }
    }
}

/// Latent adaptation: per-token Linear(C → w) + tanh, flatten (P·w) → Linear → μ, logσ² ∈ ℝ^Z; decoder
/// Linear(Z → P·w) + tanh → per-token Linear(w → C) = Δz.
#[derive(Module, Debug)]
pub struct LatentCodec {
    token_in: Linear,
    to_mu: Linear,
    to_logvar: Linear,
    from_latent: Linear,
    token_out: Linear,
    #[module(skip)]
    tokens: usize,
    #[module(skip)]
    token_width: usize,
    #[module(skip)]
    latent: usize,
}

impl FrameCodec for LatentCodec {
    type Context = ();

    fn latent_width(&self) -> usize {
        self.latent
    }

    fn encode(&self, x: Tensor<3>, _ctx: &()) -> (Tensor<2>, Tensor<2>) {
        let [b, p, _] = x.dims();
        assert_eq!(p, self.tokens, "latent codec built for {} tokens, got {p}", self.tokens);
        let flat = tanh(self.token_in.forward(x)).reshape([b, p * self.token_width]);
        let mu = self.to_mu.forward(flat.clone());
        let logvar = self.to_logvar.forward(flat).clamp(LOGVAR_MIN, LOGVAR_MAX);
        (mu, logvar)
    }

    fn decode(&self, h: Tensor<2>, _ctx: &()) -> Tensor<3> {
        let [b, _] = h.dims();
        let tokens = tanh(self.from_latent.forward(h)).reshape([b, self.tokens, self.token_width]);
        self.token_out.forward(tokens)
    }
}
