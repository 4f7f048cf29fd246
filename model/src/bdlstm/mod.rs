//! BD-LSTM baseline (Qiao et al., shared-weight bidirectional LSTM for mesh sequences): a frame codec, an LSTM
//! stack, and the free-running chains X_{t+1} = X_t + tCnv(cell(Conv(X_t), s_t)) run forward from the first frame
//! and backward from the last with the same weights (Qiao et al., Eq. 2–5), the losses (B1)–(B3) and the completion merge rule.
//!
//! Two frame representations plug in through [`FrameCodec`]: standardised trajectory latents ([`LatentCodec`],
//! ours, the default) and per-vertex ACAP features with mesh convolutions ([`MeshConvCodec`], the original).

mod codec;
mod loss;
mod merge;
mod mesh_conv;

use burn::nn::{Lstm, LstmConfig, LstmState};
use burn::prelude::*;
use burn::tensor::Distribution;

pub use crate::mesh_vae::Posterior;
pub use codec::{FrameCodec, LOGVAR_MAX, LOGVAR_MIN, LatentCodec, LatentCodecConfig};
pub use loss::{BdLstmLoss, BdLstmLossConfig, NORM_EPS, bdlstm_loss, frame_norms, kl_sum, l2_penalty};
pub use merge::{MergeConfig, MergedSegment, SegmentError, SegmentTry, bbox_diagonal, frame_distance, merge_segment};
pub use mesh_conv::{MeshConv, MeshConvCodec, MeshConvCodecConfig, MeshGraph};

/// Configuration of the recurrent part of [`BdLstm`] (the codec carries the widths).
#[derive(Config, Debug)]
pub struct BdLstmConfig {
    /// Stacked LSTM layers.
    #[config(default = 3)]
    pub layers: usize,
    /// Initial state s₀ of the forward chain, every entry of every layer's cell and hidden state; the backward
    /// chain starts from −s₀.
    #[config(default = 0.1)]
    pub initial_state: f64,
    /// Standard deviation of the perturbation ξ added to s₀ on a completion retry (s₀ + σξ forward, its negative
    /// backward).
    #[config(default = 0.1)]
    pub retry_noise: f64,
}

impl BdLstmConfig {
    /// Builds the model around `codec`: `layers` LSTMs of the codec's latent width.
    pub fn init<C: FrameCodec>(&self, codec: C, device: &Device) -> BdLstm<C> {
        let z = codec.latent_width();
        BdLstm {
            codec,
            cells: (0..self.layers)
                .map(|_| LstmConfig::new(z, z, true).init(device))
                .collect(),
            layers: self.layers,
            latent: z,
            initial_state: self.initial_state,
            retry_noise: self.retry_noise,
        }
    }
}

/// Recurrent state of one chain: (cell, hidden) of every LSTM layer, each `[B, Z]`.
#[derive(Debug, Clone)]
pub struct ChainState {
    /// One state per layer, bottom first.
    pub layers: Vec<LstmState<2>>,
}

impl ChainState {
    /// Every entry of every layer set to `value`.
    pub fn constant(layers: usize, batch: usize, width: usize, value: f64, device: &Device) -> Self {
        let t = || Tensor::<2>::full([batch, width], value, device);
        Self {
            layers: (0..layers).map(|_| LstmState::new(t(), t())).collect(),
        }
    }

    /// The state with every entry negated (the backward chain's start).
    pub fn neg(&self) -> Self {
        Self {
            layers: self
                .layers
                .iter()
                .map(|s| LstmState::new(s.cell.clone().neg(), s.hidden.clone().neg()))
                .collect(),
        }
    }

    /// Every entry plus i.i.d. N(0, σ²) noise from the device RNG.
    pub fn perturbed(&self, sigma: f64) -> Self {
        let noise =
            |t: &Tensor<2>| t.clone() + Tensor::<2>::random(t.dims(), Distribution::Normal(0.0, sigma), &t.device());
        Self {
            layers: self
                .layers
                .iter()
                .map(|s| LstmState::new(noise(&s.cell), noise(&s.hidden)))
                .collect(),
        }
    }
}

/// Initial states of the two chains; the backward one is the negated forward one.
#[derive(Debug, Clone)]
pub struct InitialStates {
    /// s₀ of the forward chain.
    pub forward: ChainState,
    /// s₀ of the backward chain.
    pub backward: ChainState,
}

/// Frames and posteriors of one chain.
#[derive(Debug, Clone)]
pub struct ChainOutput {
    /// The start frame followed by the `steps` generated ones, `[B, steps + 1, K, C]`.
    pub frames: Tensor<4>,
    /// Posterior means of the encoded frames (the start and every generated frame but the last), `[B, steps, Z]`.
    pub mu: Tensor<3>,
    /// Matching log-variances, `[B, steps, Z]`.
    pub logvar: Tensor<3>,
}

/// Both chains over one window X_1..X_n.
#[derive(Debug, Clone)]
pub struct BdLstmOutput {
    /// S^f_1..S^f_n (S^f_1 = X_1), `[B, n, K, C]`.
    pub forward: ChainOutput,
    /// S^b_1..S^b_n in the backward chain's own order (S^b_1 = X_n), `[B, n, K, C]`.
    pub backward: ChainOutput,
}

/// Shared-weight bidirectional LSTM over frames of any [`FrameCodec`].
#[derive(Module, Debug)]
pub struct BdLstm<C: Module + FrameCodec> {
    codec: C,
    cells: Vec<Lstm>,
    #[module(skip)]
    layers: usize,
    #[module(skip)]
    latent: usize,
    #[module(skip)]
    initial_state: f64,
    #[module(skip)]
    retry_noise: f64,
}

impl<C: Module + FrameCodec> BdLstm<C> {
    /// The frame codec.
    pub fn codec(&self) -> &C {
        &self.codec
    }

    /// The nominal initial states s₀^f = s₀·𝟙, s₀^b = −s₀^f.
    pub fn initial_states(&self, batch: usize, device: &Device) -> InitialStates {
        let forward = ChainState::constant(self.layers, batch, self.latent, self.initial_state, device);
        InitialStates {
            backward: forward.neg(),
            forward,
        }
    }

    /// The states of completion retry `attempt`: nominal for attempt 0, otherwise s₀^f + σξ (device RNG) and its
    /// negative.
    pub fn retry_states(&self, attempt: usize, batch: usize, device: &Device) -> InitialStates {
        let nominal = self.initial_states(batch, device);
        if attempt == 0 {
            return nominal;
        }
        let forward = nominal.forward.perturbed(self.retry_noise);
        InitialStates {
            backward: forward.neg(),
            forward,
        }
    }

    /// One recurrent step: encode X_t, run the LSTM stack, decode ΔX_t and return X_{t+1} = X_t + ΔX_t.
    ///
    /// # Shapes
    /// - `x`: `[B, K, C]` → (`[B, K, C]` next frame, `[B, Z]` μ, `[B, Z]` logσ²)
    pub fn step(
        &self,
        x: Tensor<3>,
        state: ChainState,
        ctx: &C::Context,
        posterior: Posterior,
    ) -> (Tensor<3>, Tensor<2>, Tensor<2>, ChainState) {
        let (mu, logvar) = self.codec.encode(x.clone(), ctx);
        let mut h = match posterior {
            Posterior::Mean => mu.clone(),
            Posterior::Sample => {
                let xi = Tensor::<2>::random(mu.dims(), Distribution::Normal(0.0, 1.0), &mu.device());
                mu.clone() + logvar.clone().mul_scalar(0.5).exp() * xi
            }
        };
        let mut next_state = Vec::with_capacity(self.layers);
        for (cell, s) in self.cells.iter().zip(state.layers) {
            let (out, s) = cell.forward(h.unsqueeze_dim(1), Some(s));
            h = out.squeeze_dim(1);
            next_state.push(s);
        }
        let next = x + self.codec.decode(h, ctx);
        (next, mu, logvar, ChainState { layers: next_state })
    }

    /// A free-running chain: `steps` steps from `start`, each fed its own previous output.
    ///
    /// # Shapes
    /// - `start`: `[B, K, C]` → frames `[B, steps + 1, K, C]`, μ and logσ² `[B, steps, Z]`
    pub fn chain(
        &self,
        start: Tensor<3>,
        steps: usize,
        state: ChainState,
        ctx: &C::Context,
        posterior: Posterior,
    ) -> ChainOutput {
        let [b, _, _] = start.dims();
        let device = start.device();
        let mut frames = vec![start.clone()];
        let (mut mus, mut logvars) = (Vec::with_capacity(steps), Vec::with_capacity(steps));
        let (mut x, mut s) = (start, state);
        for _ in 0..steps {
            let (next, mu, logvar, next_s) = self.step(x, s, ctx, posterior);
            frames.push(next.clone());
            mus.push(mu);
            logvars.push(logvar);
            (x, s) = (next, next_s);
        }
        let stack = |v: Vec<Tensor<2>>| {
            if v.is_empty() {
                Tensor::<3>::zeros([b, 0, self.latent], &device)
            } else {
                Tensor::stack(v, 1)
            }
        };
        ChainOutput {
            frames: Tensor::stack(frames, 1),
            mu: stack(mus),
            logvar: stack(logvars),
        }
    }

    /// Both chains over a window of n ≥ 2 frames: forward from X_1, backward from X_n, n − 1 steps each.
    ///
    /// # Shapes
    /// - `window`: `[B, n, K, C]`; outputs `[B, n, K, C]` per chain
    pub fn forward(
        &self,
        window: Tensor<4>,
        init: &InitialStates,
        ctx: &C::Context,
        posterior: Posterior,
    ) -> BdLstmOutput {
        let [b, n, k, c] = window.dims();
        assert!(n >= 2, "a BD-LSTM window needs at least 2 frames, got {n}");
        let first = window.clone().narrow(1, 0, 1).reshape([b, k, c]);
        let last = window.narrow(1, n - 1, 1).reshape([b, k, c]);
        BdLstmOutput {
            forward: self.chain(first, n - 1, init.forward.clone(), ctx, posterior),
            backward: self.chain(last, n - 1, init.backward.clone(), ctx, posterior),
        }
    }
}
