//! BD-LSTM losses (B1)–(B3) (Qiao et al., Eq. 3–5): reconstruction of both chains, agreement of the two chains, and the
//! regulariser KL + Σw². Norms are unsquared L2 over a whole frame, summed over the frames of the window and
//! averaged over the batch.

use burn::module::{ModuleVisitor, Param};
use burn::prelude::*;

use super::BdLstmOutput;

/// Added under the square root of every frame norm so that a zero difference has a finite gradient.
pub const NORM_EPS: f64 = 1e-12;

/// Weights of (B3).
#[derive(Config, Debug)]
pub struct BdLstmLossConfig {
    /// Weight of L_bidir.
    #[config(default = 0.5)]
    pub bidir_weight: f64,
    /// Weight of L_KL.
    #[config(default = 0.1)]
    pub kl_weight: f64,
    /// Weight of the L2 penalty Σw².
    #[config(default = 0.1)]
    pub l2_weight: f64,
}

/// Terms of one BD-LSTM step, each `[1]`.
#[derive(Debug, Clone)]
pub struct BdLstmLoss {
    /// (B3) total.
    pub total: Tensor<1>,
    /// (B1) L_recon.
    pub recon: Tensor<1>,
    /// (B2) L_bidir.
    pub bidir: Tensor<1>,
    /// L_KL.
    pub kl: Tensor<1>,
    /// Σw².
    pub l2: Tensor<1>,
}

/// ‖a_i − b_i‖ per sample and frame: sqrt(Σ over K·C of the squared difference + [`NORM_EPS`]).
///
/// # Shapes
/// - `a`, `b`: `[B, n, K, C]` → `[B, n]`
pub fn frame_norms(a: Tensor<4>, b: Tensor<4>) -> Tensor<2> {
    let [bs, n, _, _] = a.dims();
    (a - b)
        .powi_scalar(2)
        .sum_dim(3)
        .sum_dim(2)
        .reshape([bs, n])
        .add_scalar(NORM_EPS)
        .sqrt()
}

/// KL(N(μ, σ²) ‖ N(0, I)) summed over the latent and the encoded frames, mean over the batch.
///
/// # Shapes
/// - `mu`, `logvar`: `[B, F, Z]` → `[1]`
pub fn kl_sum(mu: Tensor<3>, logvar: Tensor<3>) -> Tensor<1> {
    let [b, _, _] = mu.dims();
    (mu.powi_scalar(2) + logvar.clone().exp() - logvar)
        .sub_scalar(1.0)
        .mul_scalar(0.5)
        .sum()
        .div_scalar(b as f64)
}

struct SquaredSum {
    total: Option<Tensor<1>>,
}

impl ModuleVisitor for SquaredSum {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let s = param.val().powi_scalar(2).sum();
        self.total = Some(match self.total.take() {
            Some(t) => t + s,
            None => s,
        });
    }
}

/// Σw² over every float parameter of `module` (differentiable), `[1]`; zero for a module without parameters.
pub fn l2_penalty<M: Module>(module: &M, device: &Device) -> Tensor<1> {
    let mut visitor = SquaredSum { total: None };
    module.visit(&mut visitor);
    visitor.total.unwrap_or_else(|| Tensor::zeros([1], device))
}

/// (B1)–(B3) for `out` on `window` X_1..X_n; `l2` is [`l2_penalty`] of the model (computed once per step).
///
/// (B1) L_recon = Σ_i ‖S^f_i − X_i‖ + ‖S^b_i − X_{n+1−i}‖; (B2) L_bidir = Σ_i ‖S^f_i − S^b_{n+1−i}‖;
/// (B3) L = L_recon + w_bidir·L_bidir + w_kl·L_KL + w_l2·Σw².
///
/// # Shapes
/// - `window`: `[B, n, K, C]`, chains as [`BdLstmOutput`]
pub fn bdlstm_loss(out: &BdLstmOutput, window: Tensor<4>, l2: Tensor<1>, cfg: &BdLstmLossConfig) -> BdLstmLoss {
    let [b, _, _, _] = window.dims();
    let f = out.forward.frames.clone();
    let back_in_time = out.backward.frames.clone().flip([1]);
    let per_batch = |t: Tensor<2>| t.sum().div_scalar(b as f64);
    let recon = per_batch(frame_norms(f.clone(), window.clone()))
        + per_batch(frame_norms(out.backward.frames.clone(), window.flip([1]))); // (B1)
    let bidir = per_batch(frame_norms(f, back_in_time)); // (B2)
    let kl = kl_sum(out.forward.mu.clone(), out.forward.logvar.clone())
        + kl_sum(out.backward.mu.clone(), out.backward.logvar.clone());
    let total = recon.clone()
        + bidir.clone().mul_scalar(cfg.bidir_weight)
        + kl.clone().mul_scalar(cfg.kl_weight)
        + l2.clone().mul_scalar(cfg.l2_weight); // (B3)
    BdLstmLoss {
        total,
        recon,
        bidir,
        kl,
        l2,
    }
}
