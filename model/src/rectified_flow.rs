//! Rectified flow with keyframes (docs/method.md §1.4, §4.2, §4.6, §5.1, §5.4): interpolant (R1), target (R2), loss
//! (R5), ODE sampling (R6) with CFG, the sampling-time replacement baseline (R7)–(R8) and impute-until-τ* (R9).
//!
//! **Convention, stated once:** τ = 0 is pure Gaussian noise, τ = 1 is data. X_τ = (1 − τ) ε + τ X₁, the target
//! velocity is X₁ − ε, and sampling integrates from τ = 0 to τ = 1. This is the reverse of SD3's σ and of DDPM step
//! indices. Keyframe masks are "observed = 1". All latent tensors are token-major `[B, P, T, C]` (the layout of the
//! network output; see `mmdit::build_input`).

use burn::prelude::*;
use burn::tensor::Distribution;
use serde::{Deserialize, Serialize};

use crate::anchor::{anchor_of, lift};
use crate::mmdit::{
    Anchor, KeyframeConditioning, Mmdit, Prediction, SceneInput, assemble_input, build_input, replace_keyframes,
    split_output,
};

// ---------------------------------------------------------------------------------------------------------------
// Training: interpolant, target, τ sampling, loss

/// (R1) X_τ = (1 − τ) ε + τ X₁, per sample τ.
///
/// # Shapes
/// - eps, x1: `[B, P, T, C]`; tau: `[B]`; output `[B, P, T, C]`
pub fn interpolant(eps: Tensor<4>, x1: Tensor<4>, tau: Tensor<1>) -> Tensor<4> {
    let [b] = tau.dims();
    let tau = tau.reshape([b, 1, 1, 1]);
    // (R1)
    eps * tau.clone().neg().add_scalar(1.0) + x1 * tau
}

/// (R2) target velocity v* = X₁ − ε (constant along the straight path).
///
/// # Shapes
/// - eps, x1: `[B, P, T, C]`; output `[B, P, T, C]`
pub fn target_velocity(eps: Tensor<4>, x1: Tensor<4>) -> Tensor<4> {
    x1 - eps // (R2)
}

/// Smallest 1 − τ in the training velocity of a data-predicting network (docs/method.md §4.9): keeps
/// (Ẑ − X_τ)/(1 − τ) and its loss bounded as τ → 1 (training draws τ up to 1). Sampling never evaluates at τ = 1 and
/// divides by the exact 1 − τ (a scalar, in f64), so that the last step lands on Ẑ.
pub const DATA_PREDICTION_MIN_GAP: f64 = 0.05;

/// The velocity that a network output stands for (docs/method.md §4.9): the output itself for
/// [`Prediction::Velocity`]; (Ẑ − X_τ) / max(1 − τ, `min_gap`) for [`Prediction::Data`], with X_τ the interpolant
/// (R1) (in sampling: the ODE state), not the network input with keyframes written in.
///
/// # Shapes
/// - output, x_tau: `[B, P, T, C]`; tau: `[B]`; returns `[B, P, T, C]`
pub fn output_velocity(
    prediction: Prediction,
    output: Tensor<4>,
    x_tau: Tensor<4>,
    tau: Tensor<1>,
    min_gap: f64,
) -> Tensor<4> {
    match prediction {
        Prediction::Velocity => output,
        Prediction::Data => {
            let [b] = tau.dims();
            let gap = tau.neg().add_scalar(1.0).clamp_min(min_gap).reshape([b, 1, 1, 1]);
            (output - x_tau) / gap
        }
    }
}

/// Distribution of the training time τ (docs/method.md §4.5 step 4, §8 X7).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TauSampler {
    /// τ ~ U(0, 1) (paper).
    Uniform,
    /// τ = 1 − 1/(tan(πu/2) + 1), u ~ U(0, 1) (SD3 "cosmap", AAM code).
    Cosmap,
    /// τ = sigmoid(n), n ~ N(mean, std²) (SD3's logit-normal; a negative mean favours the noisy end, τ near 0).
    LogitNormal { mean: f64, std: f64 },
}

impl TauSampler {
    /// Maps uniform draws u ∈ (0, 1) to τ (the logit-normal through the normal quantile of u).
    ///
    /// # Shapes
    /// - u, output: `[B]`
    pub fn map(self, u: Tensor<1>) -> Tensor<1> {
        match self {
            TauSampler::Uniform => u,
            TauSampler::Cosmap => {
                let half_pi_u = u.mul_scalar(std::f64::consts::FRAC_PI_2);
                let (s, c) = (half_pi_u.clone().sin(), half_pi_u.cos());
                s.clone() / (s + c) // = 1 − 1/(tan(πu/2) + 1), without the pole of tan at u = 1
            }
            TauSampler::LogitNormal { mean, std } => {
                let device = u.device();
                let [b] = u.dims();
                let us = u
                    .into_data()
                    .convert::<f64>()
                    .try_to_vec::<f64>()
                    .expect("a tensor converted to f64 reads back as f64");
                let n: Vec<f32> = us.iter().map(|&p| (mean + std * normal_quantile(p)) as f32).collect();
                burn::tensor::activation::sigmoid(Tensor::from_data(TensorData::new(n, [b]), &device))
            }
        }
    }

    /// Draws B times from `rng` on the host ([`crate::noise`]): the same τ on every backend and thread.
    pub fn sample_with(self, batch: usize, rng: &mut impl any4d_data::rng::Rng, device: &Device) -> Tensor<1> {
        self.map(crate::noise::uniform_open(batch, rng, device))
    }

    /// Draws B times from the device's random stream (seed it with `device.seed`).
    pub fn sample(self, batch: usize, device: &Device) -> Tensor<1> {
        match self {
            TauSampler::LogitNormal { mean, std } => {
                burn::tensor::activation::sigmoid(Tensor::random([batch], Distribution::Normal(mean, std), device))
            }
            _ => self.map(Tensor::random([batch], Distribution::Uniform(0.0, 1.0), device)),
        }
    }

    /// Checks the parameters; the error names the field.
    pub fn validate(self) -> Result<(), String> {
        match self {
            TauSampler::LogitNormal { mean, std } if !(mean.is_finite() && std.is_finite() && std > 0.0) => {
                Err(format!(
                    "rf.tau_sampler.logit_normal needs a finite mean and a positive finite std, got {mean} and {std}"
                ))
            }
            _ => Ok(()),
        }
    }
}

/// The standard normal quantile Φ⁻¹(p) for p ∈ (0, 1) (Acklam's rational approximation, relative error < 1.2e-9);
/// ±∞ at the ends.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    const P_LOW: f64 = 0.02425;
    if p < P_LOW {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - P_LOW {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Which slots enter the loss (docs/method.md §4.2, `rf.loss_on_keyframes`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeyframeLoss {
    /// All T slots, keyframes included (paper, P-Eq. 10 unchanged).
    All,
    /// Only m = 0 slots (CondMDI variant).
    NonKeyframesOnly,
}

/// (R5) L_RF = mean of (v_θ − v*)² over B, P, T, C — or over the m = 0 slots only.
///
/// # Shapes
/// - v_pred, v_target: `[B, P, T, C]`; mask: `[B, T]` (1 = keyframe); output `[1]`
pub fn rf_loss(v_pred: Tensor<4>, v_target: Tensor<4>, mask: Tensor<2>, keyframe_loss: KeyframeLoss) -> Tensor<1> {
    let se = (v_pred - v_target).square();
    match keyframe_loss {
        KeyframeLoss::All => se.mean(), // (R5)
        KeyframeLoss::NonKeyframesOnly => {
            let [b, p, t, c] = se.dims();
            let keep = mask.neg().add_scalar(1.0).reshape([b, 1, t, 1]);
            let count = keep.clone().sum().mul_scalar((p * c) as f64).clamp_min(1.0);
            (se * keep).sum() / count
        }
    }
}

/// Replacement mask of (R9): m where τ < τ*, 0 after the cutoff (per sample).
///
/// # Shapes
/// - mask: `[B, T]`; tau: `[B]`; output `[B, T]`
pub fn impute_mask(mask: Tensor<2>, tau: Tensor<1>, tau_star: f64) -> Tensor<2> {
    let [b] = tau.dims();
    let before = tau.lower_elem(tau_star).float().reshape([b, 1]);
    mask * before
}

/// One training batch of the keyframe RF (docs/method.md §4.5), standardized latents.
pub struct RfBatch {
    /// Shape latent z₀, `[B, P, C]`.
    pub z0: Tensor<3>,
    /// Trajectory latents Z (slots 1..T), `[B, P, T, C]`.
    pub z: Tensor<4>,
    /// Keyframe latents given to the network, `[B, P, T, C]`: Z itself for `InputMask`, the noisy keyframes for
    /// `ImputeUntil`; ignored for `ReplaceNoised` / `None` (trained without keyframes).
    pub z_key: Tensor<4>,
    /// Keyframe mask m, `[B, T]`, 1 = observed.
    pub mask: Tensor<2>,
    /// Text token states, `[B, L, D_txt]`.
    pub text: Tensor<3>,
    /// 1 = keep the caption, 0 = dropped (CFG training), `[B]`.
    pub keep_txt: Tensor<1>,
    /// The clips' scenes, for a network that reads them (docs/method.md §4.12); `None` = no scene.
    pub scene: Option<SceneInput>,
}

/// Options of the RF objective.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RfLossOptions {
    /// Keyframe mode of the network.
    pub conditioning: KeyframeConditioning,
    /// Which slots enter (R5).
    pub keyframe_loss: KeyframeLoss,
    /// τ* of (R9), used by `KeyframeConditioning::ImputeUntil` only.
    pub tau_star: f64,
}

/// The RF loss of one batch for given noise ε and times τ: (R1), (R3), (R4), (R2), (R5).
///
/// # Shapes
/// - eps: `[B, P, T, C]`; tau: `[B]`; output `[1]`
pub fn rf_training_loss(
    model: &Mmdit,
    batch: &RfBatch,
    eps: Tensor<4>,
    tau: Tensor<1>,
    opts: &RfLossOptions,
) -> Tensor<1> {
    let [_, _, frames, _] = batch.z.dims();
    // docs/method.md §4.10, (R11): with an anchor the flow's data end is the scaled residual X₁ = (Z − A)/s, and the
    // network sees the state as latents, A + s X_τ.
    let anchor = anchor_of(model.anchor(), &batch.z_key, &batch.mask);
    let x1 = match &anchor {
        Some((a, s)) => (batch.z.clone() - a.clone()).div_scalar(*s),
        None => batch.z.clone(),
    };
    let x_state = interpolant(eps.clone(), x1.clone(), tau.clone()); // (R1)
    let x_tau = lift(&anchor, x_state.clone());
    let mask = match opts.conditioning {
        KeyframeConditioning::InputMask => batch.mask.clone(),
        KeyframeConditioning::ImputeUntil => impute_mask(batch.mask.clone(), tau.clone(), opts.tau_star),
        KeyframeConditioning::ReplaceNoised | KeyframeConditioning::None => batch.mask.zeros_like(),
    };
    let input = match opts.conditioning {
        // (R9): replacement before τ* only, but the mask channel carries m throughout.
        KeyframeConditioning::ImputeUntil => {
            let state = replace_keyframes(x_tau, batch.z_key.clone(), mask);
            assemble_input(batch.z0.clone(), state, batch.mask.clone(), opts.conditioning)
        }
        _ => build_input(
            batch.z0.clone(),
            x_tau,
            mask.clone(),
            batch.z_key.clone(),
            opts.conditioning,
        ), // (R3)
    };
    let out = split_output(
        model.forward_in_scene(
            input,
            batch.text.clone(),
            batch.keep_txt.clone(),
            tau.clone(),
            batch.scene.as_ref(),
        ),
        frames,
    ); // (R4)
    let v = output_velocity(model.prediction(), out, x_state, tau, DATA_PREDICTION_MIN_GAP);
    rf_loss(v, target_velocity(eps, x1), batch.mask.clone(), opts.keyframe_loss)
}

// ---------------------------------------------------------------------------------------------------------------
// Sampling

/// ODE solver on a uniform grid (docs/method.md §4.6, §9 item 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// X ← X + Δ v(X, τ) (P-Eq. 6 / 12).
    Euler,
    /// X ← X + Δ v(X + Δ/2 · v(X, τ), τ + Δ/2) (P-Table S3, `torchdiffeq` "midpoint").
    Midpoint,
}

/// Noise that re-noises the keyframes of the replacement sampler (docs/method.md §5.1, §8 X9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReplaceNoise {
    /// ε_key = the initial noise ε of those slots, fixed for the trajectory.
    Fixed,
    /// New N(0, I) noise at every evaluation, from [`sampler_noise`] seeded by `SampleOptions::fresh_seed` and τ.
    Fresh,
}

/// Sampler settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleOptions {
    /// Grid points over [0, 1], n_grid − 1 steps (64 in the paper).
    pub n_grid: usize,
    /// Solver.
    pub solver: Solver,
    /// How the keyframes enter: decides (R3), (R7) or (R9) and the input width.
    pub conditioning: KeyframeConditioning,
    /// Noise of (R7), for `KeyframeConditioning::ReplaceNoised`.
    pub replace_noise: ReplaceNoise,
    /// τ* of (R9), for `KeyframeConditioning::ImputeUntil`.
    pub tau_star: f64,
    /// Seed of `ReplaceNoise::Fresh` draws (each evaluation mixes in its τ).
    pub fresh_seed: u64,
    /// Scale s of the sampler's noise (docs/method.md §4.6, X14): the ODE starts at X₀ = s ε, and fresh replacement
    /// noise is drawn as s ε too. 1 in the paper; s = 0 gives one deterministic completion per input (s < 1 is not a
    /// temperature for a flow trained on unit noise: docs/method.md §4.6).
    pub noise_scale: f64,
}

impl SampleOptions {
    /// Paper defaults: midpoint, 64 grid points, fixed replacement noise, τ* = 0.98.
    pub fn paper(conditioning: KeyframeConditioning) -> Self {
        Self {
            n_grid: 64,
            solver: Solver::Midpoint,
            conditioning,
            replace_noise: ReplaceNoise::Fixed,
            tau_star: 0.98,
            fresh_seed: 0,
            noise_scale: 1.0,
        }
    }
}

/// What stays fixed during sampling: the shape latent, the keyframe latents and the mask (also for the
/// unconditional CFG branch).
#[derive(Clone, Debug)]
pub struct Conditioning {
    /// Shape latent z₀, `[B, P, C]`.
    pub z0: Tensor<3>,
    /// Keyframe latents Z_key (anything where mask = 0), `[B, P, T, C]`.
    pub z_key: Tensor<4>,
    /// Keyframe mask m, `[B, T]`, 1 = observed.
    pub mask: Tensor<2>,
    /// The clips' scenes, for a network that reads them (docs/method.md §4.12); `None` = no scene.
    pub scene: Option<SceneInput>,
}

/// The network input at one evaluation: (R3), (R7) or (R9) depending on the mode.
///
/// # Shapes
/// - x: `[B, P, T, C]` ODE state; eps: `[B, P, T, C]` the initial noise; output `[B, P, in_channels]`
pub fn sampler_input(cond: &Conditioning, x: Tensor<4>, eps: &Tensor<4>, tau: f64, opts: &SampleOptions) -> Tensor<3> {
    let (z0, mask) = (cond.z0.clone(), cond.mask.clone());
    match opts.conditioning {
        KeyframeConditioning::InputMask => {
            build_input(z0, x, mask, cond.z_key.clone(), KeyframeConditioning::InputMask)
        } // (R3)
        KeyframeConditioning::ReplaceNoised => {
            let eps_key = match opts.replace_noise {
                ReplaceNoise::Fixed => eps.clone(),
                ReplaceNoise::Fresh => {
                    let seed = any4d_data::rng::splitmix64(opts.fresh_seed ^ tau.to_bits());
                    scale_noise(sampler_noise(seed, eps.dims(), &eps.device()), opts.noise_scale)
                }
            };
            // (R7) keyframe latent noised to the state's level: (1 − τ) ε_key + τ Z_key
            let key_tau = eps_key.mul_scalar(1.0 - tau) + cond.z_key.clone().mul_scalar(tau);
            build_input(z0, x, mask, key_tau, KeyframeConditioning::ReplaceNoised)
        }
        KeyframeConditioning::ImputeUntil => {
            // (R9) clean (or noisy-observed) keyframes imputed only while τ < τ*; the mask channel stays.
            let state = if tau < opts.tau_star {
                replace_keyframes(x, cond.z_key.clone(), mask.clone())
            } else {
                x
            };
            assemble_input(z0, state, mask, KeyframeConditioning::ImputeUntil)
        }
        KeyframeConditioning::None => assemble_input(z0, x, mask, KeyframeConditioning::None),
    }
}

/// Integrates (R6) from τ = 0 (X = ε) to τ = 1 with a velocity closure `velocity(input [B, P, in], τ [B]) →
/// [B, P, T·C]`, rebuilding the input at **every** evaluation; then overwrites keyframe slots with Z_key
/// (`InputMask`, `ReplaceNoised`; `ImputeUntil` keeps its denoised keyframes, `None` has none).
///
/// # Shapes
/// - eps: `[B, P, T, C]` initial noise; output `[B, P, T, C]` (standardized latents X₁)
///
/// # Panics
/// If `opts.n_grid < 2`.
pub fn sample<F>(velocity: F, cond: &Conditioning, eps: Tensor<4>, opts: &SampleOptions) -> Tensor<4>
where
    F: FnMut(Tensor<3>, Tensor<1>) -> Tensor<3>,
{
    sample_outputs(velocity, Prediction::Velocity, Anchor::None, cond, eps, opts)
}

/// [`sample`] for a closure whose output is `prediction` (velocities or clean latents, docs/method.md §4.9),
/// turned into the velocity of (R6) at every evaluation by [`output_velocity`] with the current ODE state, for a flow
/// that generates what `anchor` says (docs/method.md §4.10: with an anchor the state is the scaled residual, lifted to
/// latents A + s x for the network input and at the end).
///
/// # Shapes
/// - eps: `[B, P, T, C]` initial noise; output `[B, P, T, C]`
///
/// # Panics
/// If `opts.n_grid < 2`.
pub fn sample_outputs<F>(
    mut network: F,
    prediction: Prediction,
    anchor: Anchor,
    cond: &Conditioning,
    eps: Tensor<4>,
    opts: &SampleOptions,
) -> Tensor<4>
where
    F: FnMut(Tensor<3>, Tensor<1>) -> Tensor<3>,
{
    assert!(
        opts.n_grid >= 2,
        "sample: n_grid must be at least 2, got {}",
        opts.n_grid
    );
    let [b, _, frames, _] = eps.dims();
    let device = eps.device();
    let eps = scale_noise(eps, opts.noise_scale);
    let anchor = anchor_of(anchor, &cond.z_key, &cond.mask);
    let mut eval = |x: Tensor<4>, tau: f64| -> Tensor<4> {
        let input = sampler_input(cond, lift(&anchor, x.clone()), &eps, tau, opts);
        let tau_b = Tensor::<1>::full([b], tau, &device);
        let out = split_output(network(input, tau_b), frames);
        match prediction {
            Prediction::Velocity => out,
            // (R10) with the exact 1 − τ, in f64 (evaluations are at τ < 1: grid points and midpoints before the end),
            // so the last step lands on Ẑ in any tensor precision.
            Prediction::Data => (out - x).mul_scalar(1.0 / (1.0 - tau)),
        }
    };
    let steps = opts.n_grid - 1;
    let dt = 1.0 / steps as f64;
    let mut x = eps.clone(); // X_0 = s ε
    for i in 0..steps {
        let tau = i as f64 * dt;
        x = match opts.solver {
            Solver::Euler => x.clone() + eval(x, tau).mul_scalar(dt),
            Solver::Midpoint => {
                let k1 = eval(x.clone(), tau);
                let x_mid = x.clone() + k1.mul_scalar(dt / 2.0);
                x + eval(x_mid, tau + dt / 2.0).mul_scalar(dt)
            }
        };
    }
    let x = lift(&anchor, x);
    match opts.conditioning {
        KeyframeConditioning::InputMask | KeyframeConditioning::ReplaceNoised => {
            replace_keyframes(x, cond.z_key.clone(), cond.mask.clone())
        }
        KeyframeConditioning::ImputeUntil | KeyframeConditioning::None => x,
    }
}

/// s ε, leaving ε as it is (bit for bit) at the paper's s = 1.
fn scale_noise(eps: Tensor<4>, scale: f64) -> Tensor<4> {
    if scale == 1.0 { eps } else { eps.mul_scalar(scale) }
}

/// Classifier-free guidance v = v_u + w (v_c − v_u).
pub fn cfg_combine(v_cond: Tensor<3>, v_uncond: Tensor<3>, guidance: f64) -> Tensor<3> {
    v_uncond.clone() + (v_cond - v_uncond).mul_scalar(guidance)
}

/// The MMDiT as a velocity closure for [`sample`], with CFG. For w = 1 only the conditional branch runs (keep_txt =
/// `keep`: 1, or 0 for a caption with no text, [`crate::text::caption_keep`]); otherwise both branches run as one
/// batch of 2B, the unconditional one with keep_txt = 0 and the same input (same z₀, keyframes, mask and scene:
/// guidance is on the caption only).
///
/// # Shapes
/// - text: `[B, L, D_txt]`; keep: `[B]`; the closure maps `[B, P, in]`, `[B]` to `[B, P, T·C]`
pub fn mmdit_velocity(
    model: &Mmdit,
    text: Tensor<3>,
    keep: Tensor<1>,
    guidance: f64,
    scene: Option<SceneInput>,
) -> impl FnMut(Tensor<3>, Tensor<1>) -> Tensor<3> + '_ {
    let doubled = scene.as_ref().filter(|_| guidance != 1.0).map(SceneInput::doubled);
    move |input: Tensor<3>, tau: Tensor<1>| {
        let [b, _, _] = input.dims();
        let device = input.device();
        if guidance == 1.0 {
            return model.forward_in_scene(input, text.clone(), keep.clone(), tau, scene.as_ref());
        }
        let keep = Tensor::cat(vec![keep.clone(), Tensor::zeros([b], &device)], 0);
        let v = model.forward_in_scene(
            Tensor::cat(vec![input.clone(), input], 0),
            Tensor::cat(vec![text.clone(), text.clone()], 0),
            keep,
            Tensor::cat(vec![tau.clone(), tau], 0),
            doubled.as_ref(),
        );
        let v_cond = v.clone().narrow(0, 0, b);
        let v_uncond = v.narrow(0, b, b);
        cfg_combine(v_cond, v_uncond, guidance)
    }
}

/// Samples trajectory latents with the MMDiT (docs/method.md §4.6): [`sample`] over [`mmdit_velocity`].
///
/// # Shapes
/// - text: `[B, L, D_txt]`; keep: `[B]` keep_txt of the conditional branch; eps: `[B, P, T, C]`; output
///   `[B, P, T, C]`
pub fn sample_mmdit(
    model: &Mmdit,
    cond: &Conditioning,
    text: Tensor<3>,
    keep: Tensor<1>,
    eps: Tensor<4>,
    guidance: f64,
    opts: &SampleOptions,
) -> Tensor<4> {
    sample_outputs(
        mmdit_velocity(model, text, keep, guidance, cond.scene.clone()),
        model.prediction(),
        model.anchor(),
        cond,
        eps,
        opts,
    )
}

/// RNG stream of the sampler's noise (distinct from the keyframe-noise stream of the evaluation).
const NOISE_STREAM: u64 = 0x7266_6570; // "rfep"

/// N(0, I) noise for `seed` from a ChaCha stream (Box–Muller) on the host: a seed gives the same noise on every
/// device and thread (the sampler's initial ε, and fresh replacement noise).
///
/// # Shapes
/// `dims` = `[B, P, T, C]`; returns `dims`.
pub fn sampler_noise(seed: u64, dims: [usize; 4], device: &Device) -> Tensor<4> {
    use any4d_data::rng::{Rng, rng};
    let mut r = rng(seed, NOISE_STREAM);
    let len = dims.iter().product();
    let values: Vec<f32> = (0..len)
        .map(|_| {
            let (u1, u2): (f64, f64) = (r.random::<f64>().max(f64::MIN_POSITIVE), r.random::<f64>());
            ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
        })
        .collect();
    Tensor::from_data(TensorData::new(values, dims), device)
}
