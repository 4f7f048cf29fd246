//! Tests of the keyframe RF (docs/method.md §1.4 required tests, §4.1 layout, §4.3 backbone, §4.6 sampling, §5.1,
//! §5.4), on tiny configs and the flex CPU backend. Tests that draw random numbers hold `SEED_LOCK`: the backend's
//! seed is global, and the determinism test must not interleave with other draws.

use std::sync::Mutex;

use any4d_model::mmdit::{
    Anchor, KeyframeConditioning, Mmdit, MmditConfig, Prediction, TIME_FREQS, build_input, merge_slots, split_output,
    timestep_sinusoid,
};
use any4d_model::rectified_flow::{
    Conditioning, DATA_PREDICTION_MIN_GAP, KeyframeLoss, ReplaceNoise, RfBatch, RfLossOptions, SampleOptions, Solver,
    TauSampler, cfg_combine, interpolant, mmdit_velocity, normal_quantile, output_velocity, rf_loss, rf_training_loss,
    sample, sample_outputs, target_velocity,
};
use any4d_model::summary::param_report;
use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{AdamWConfig, GradientsParams};
use burn::prelude::*;
use burn::tensor::{Distribution, TensorData};

static SEED_LOCK: Mutex<()> = Mutex::new(());

fn lock() -> std::sync::MutexGuard<'static, ()> {
    SEED_LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

fn dev() -> Device {
    Device::flex()
}

fn normal<const D: usize>(shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::random(shape, Distribution::Normal(0.0, 1.0), device)
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec().expect("f32 data")
}

fn max_abs_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    values(a)
        .iter()
        .zip(values(b))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Keyframes at frames 0 and T−1 for every sample.
fn first_last_mask(b: usize, t: usize, device: &Device) -> Tensor<2> {
    let mut m = vec![0f32; b * t];
    for i in 0..b {
        m[i * t] = 1.0;
        m[i * t + t - 1] = 1.0;
    }
    Tensor::from_data(TensorData::new(m, [b, t]), device)
}

// ----------------------------------------------------------------------------------------------------------------
// docs/method.md §1.4 (1): interpolant direction

#[test]
fn interpolant_is_noise_at_zero_and_data_at_one() {
    let _g = lock();
    let d = dev();
    let eps = normal([2, 5, 4, 3], &d);
    let x1 = normal([2, 5, 4, 3], &d);
    let at0 = interpolant(eps.clone(), x1.clone(), Tensor::zeros([2], &d));
    let at1 = interpolant(eps.clone(), x1.clone(), Tensor::ones([2], &d));
    assert!(max_abs_diff(at0, eps.clone()) < 1e-7, "X_0 must be ε");
    assert!(max_abs_diff(at1, x1.clone()) < 1e-7, "X_1 must be the data");
    // Per-sample τ: sample 0 at τ = 0.25 is 0.75 ε + 0.25 x1.
    let mixed = interpolant(eps.clone(), x1.clone(), Tensor::from_floats([0.25, 1.0], &d));
    let expect = eps.clone().mul_scalar(0.75) + x1.clone().mul_scalar(0.25);
    assert!(max_abs_diff(mixed.narrow(0, 0, 1), expect.narrow(0, 0, 1)) < 1e-6);
    // (R2) target points from noise to data.
    assert!(max_abs_diff(target_velocity(eps.clone(), x1.clone()), x1 - eps) < 1e-7);
}

// ----------------------------------------------------------------------------------------------------------------
// docs/method.md §1.4 (2): the oracle velocity carries ε to x₁ with both solvers

#[test]
fn oracle_velocity_maps_noise_to_data_euler_and_midpoint() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (2, 6, 4, 3);
    let eps = normal([b, p, t, c], &d);
    let x1 = normal([b, p, t, c], &d);
    let cond = Conditioning {
        z0: normal([b, p, c], &d),
        z_key: x1.zeros_like(),
        mask: Tensor::zeros([b, t], &d),
        scene: None,
    };
    for solver in [Solver::Euler, Solver::Midpoint] {
        let opts = SampleOptions {
            n_grid: 64,
            solver,
            ..SampleOptions::paper(KeyframeConditioning::None)
        };
        let oracle = merge_slots(x1.clone() - eps.clone());
        let out = sample(|_input, _tau| oracle.clone(), &cond, eps.clone(), &opts);
        let err = max_abs_diff(out, x1.clone());
        assert!(err < 1e-5, "{solver:?}: max error {err}");
    }
}

/// docs/method.md §8 X14: `noise_scale = s` is the sampler started from s ε, whatever reads ε — the ODE state and
/// the fixed replacement noise of (R7) alike; s = 0 forgets ε.
#[test]
fn noise_scale_starts_the_sampler_from_scaled_noise() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (2, 5, 4, 3);
    let eps = normal([b, p, t, c], &d);
    let mut mask = vec![0.0f32; b * t];
    mask[1] = 1.0; // frame 1 of window 0 is a keyframe: its input is (1 − τ) ε_key + τ Z_key
    let cond = Conditioning {
        z0: normal([b, p, c], &d),
        z_key: normal([b, p, t, c], &d),
        mask: Tensor::from_data(TensorData::new(mask, [b, t]), &d),
        scene: None,
    };
    // A velocity that reads its whole input (state, keyframe channels and mask), so any ε it sees shows.
    let net = |input: Tensor<3>, tau: Tensor<1>| {
        let [bb, pp, _] = input.dims();
        let every = input.clone().sum_dim(2).tanh().expand([bb, pp, t * c]);
        input.narrow(2, 0, t * c).tanh() + every + tau.reshape([bb, 1, 1]).expand([bb, pp, t * c]).mul_scalar(0.5)
    };
    for conditioning in [KeyframeConditioning::InputMask, KeyframeConditioning::ReplaceNoised] {
        let paper = SampleOptions {
            n_grid: 5,
            ..SampleOptions::paper(conditioning)
        };
        let scaled = SampleOptions {
            noise_scale: 0.5,
            ..paper
        };
        let a = sample(net, &cond, eps.clone(), &scaled);
        let b_ = sample(net, &cond, eps.clone().mul_scalar(0.5), &paper);
        assert!(
            max_abs_diff(a.clone(), b_) < 1e-6,
            "{conditioning:?}: s = 0.5 is not the sampler from ε / 2"
        );
        let unscaled = sample(net, &cond, eps.clone(), &paper);
        assert!(
            max_abs_diff(a, unscaled) > 1e-3,
            "{conditioning:?}: the scale changed nothing"
        );
        let zero = SampleOptions {
            noise_scale: 0.0,
            ..paper
        };
        let one = sample(net, &cond, eps.clone(), &zero);
        let other = sample(net, &cond, normal([b, p, t, c], &d), &zero);
        assert!(
            max_abs_diff(one, other) < 1e-7,
            "{conditioning:?}: s = 0 still depends on ε"
        );
    }
}

/// docs/method.md §4.9: a network that outputs the clean latents Z* moves the state straight towards them and lands
/// on them exactly, on any grid and with either solver (the sampler divides by the exact 1 − τ).
#[test]
fn a_data_predicting_oracle_lands_on_its_prediction_on_every_grid() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (2, 5, 4, 3);
    let eps = normal([b, p, t, c], &d);
    let x1 = normal([b, p, t, c], &d);
    let cond = Conditioning {
        z0: normal([b, p, c], &d),
        z_key: x1.zeros_like(),
        mask: Tensor::zeros([b, t], &d),
        scene: None,
    };
    for n_grid in [2, 16, 64] {
        for solver in [Solver::Euler, Solver::Midpoint] {
            let opts = SampleOptions {
                n_grid,
                solver,
                ..SampleOptions::paper(KeyframeConditioning::None)
            };
            let oracle = merge_slots(x1.clone());
            let out = sample_outputs(
                |_input, _tau| oracle.clone(),
                Prediction::Data,
                Anchor::None,
                &cond,
                eps.clone(),
                &opts,
            );
            let err = max_abs_diff(out, x1.clone());
            assert!(err < 1e-4, "{solver:?}, {n_grid} points: max error {err}");
        }
    }
}

/// docs/method.md §4.9: the velocity of a data prediction is (Ẑ − X_τ) / (1 − τ), with 1 − τ floored at
/// `min_gap`; a velocity prediction passes through.
#[test]
fn data_predictions_become_velocities_with_a_floored_gap() {
    let _g = lock();
    let d = dev();
    let z = normal([2, 3, 4, 2], &d);
    let x = normal([2, 3, 4, 2], &d);
    let tau = Tensor::<1>::from_data(TensorData::new(vec![0.25f32, 0.99], [2]), &d);
    let v = output_velocity(
        Prediction::Data,
        z.clone(),
        x.clone(),
        tau.clone(),
        DATA_PREDICTION_MIN_GAP,
    );
    let want_0 = (z.clone().narrow(0, 0, 1) - x.clone().narrow(0, 0, 1)).div_scalar(0.75);
    let want_1 = (z.clone().narrow(0, 1, 1) - x.clone().narrow(0, 1, 1)).div_scalar(DATA_PREDICTION_MIN_GAP);
    assert!(max_abs_diff(v.clone().narrow(0, 0, 1), want_0) < 1e-5);
    assert!(max_abs_diff(v.narrow(0, 1, 1), want_1) < 1e-4);
    let same = output_velocity(Prediction::Velocity, z.clone(), x, tau, DATA_PREDICTION_MIN_GAP);
    assert_eq!(max_abs_diff(same, z), 0.0);
}

// ----------------------------------------------------------------------------------------------------------------
// docs/method.md §1.4 (3): replacement weights the keyframe latent by τ

#[test]
fn replacement_noises_keyframes_to_the_state_level() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (1, 3, 4, 2);
    let eps = normal([b, p, t, c], &d);
    let z_key = normal([b, p, t, c], &d);
    let mask = Tensor::from_data(TensorData::new(vec![0f32, 1.0, 0.0, 0.0], [b, t]), &d);
    let cond = Conditioning {
        z0: Tensor::zeros([b, p, c], &d),
        z_key: z_key.clone(),
        mask,
        scene: None,
    };
    let opts = SampleOptions {
        n_grid: 5,
        solver: Solver::Euler,
        ..SampleOptions::paper(KeyframeConditioning::ReplaceNoised)
    };
    let mut seen = Vec::new();
    let out = sample(
        |input: Tensor<3>, tau: Tensor<1>| {
            assert_eq!(input.dims()[2], (t + 1) * c, "ReplaceNoised has no mask channels");
            let tau_v = values(tau)[0] as f64;
            // slot 2 (frame 1) occupies channels [2c, 3c) of the input
            let got = input.narrow(2, 2 * c, c);
            let want = (eps.clone().mul_scalar(1.0 - tau_v) + z_key.clone().mul_scalar(tau_v)).narrow(2, 1, 1);
            seen.push((tau_v, max_abs_diff(got, want.reshape([b, p, c]))));
            Tensor::zeros([b, p, t * c], &d)
        },
        &cond,
        eps.clone(),
        &opts,
    );
    assert_eq!(seen.len(), 4);
    for (tau, err) in &seen {
        assert!(
            *err < 1e-6,
            "at τ = {tau} the keyframe slot is not (1−τ)ε + τ z_key (err {err})"
        );
    }
    // Keyframe slots are clamped to Z_key at the end (exactly), others keep the state (here ε, zero velocity).
    let out_key = out.clone().narrow(2, 1, 1);
    assert_eq!(values(out_key), values(z_key.narrow(2, 1, 1)));
    assert_eq!(values(out.narrow(2, 0, 1)), values(eps.narrow(2, 0, 1)));
}

#[test]
fn fresh_replacement_noise_differs_from_fixed() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (1, 3, 2, 2);
    let eps = normal([b, p, t, c], &d);
    let cond = Conditioning {
        z0: Tensor::zeros([b, p, c], &d),
        z_key: Tensor::zeros([b, p, t, c], &d),
        mask: Tensor::ones([b, t], &d),
        scene: None,
    };
    let first_input = |noise: ReplaceNoise| {
        let opts = SampleOptions {
            n_grid: 2,
            solver: Solver::Euler,
            replace_noise: noise,
            ..SampleOptions::paper(KeyframeConditioning::ReplaceNoised)
        };
        let mut got = None;
        sample(
            |input: Tensor<3>, _| {
                got.get_or_insert(input);
                Tensor::zeros([b, p, t * c], &d)
            },
            &cond,
            eps.clone(),
            &opts,
        );
        got.expect("one evaluation")
    };
    let fixed = first_input(ReplaceNoise::Fixed);
    let fresh = first_input(ReplaceNoise::Fresh);
    // At τ = 0 the fixed keyframe input is exactly ε; fresh noise is another draw.
    assert!(max_abs_diff(fixed.clone().narrow(2, c, t * c), merge_slots(eps.clone())) < 1e-7);
    assert!(max_abs_diff(fixed, fresh) > 1e-3);
}

// ----------------------------------------------------------------------------------------------------------------
// docs/method.md §1.4 (4): the network receives τ, increasing from 0, never 1 − τ

#[test]
fn sampler_passes_tau_increasing_from_zero() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (2, 3, 2, 2);
    let cond = Conditioning {
        z0: Tensor::zeros([b, p, c], &d),
        z_key: Tensor::zeros([b, p, t, c], &d),
        mask: Tensor::zeros([b, t], &d),
        scene: None,
    };
    for (solver, expected) in [
        (Solver::Euler, vec![0.0, 0.25, 0.5, 0.75]),
        (Solver::Midpoint, vec![0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875]),
    ] {
        let opts = SampleOptions {
            n_grid: 5,
            solver,
            ..SampleOptions::paper(KeyframeConditioning::InputMask)
        };
        let mut taus = Vec::new();
        sample(
            |_, tau: Tensor<1>| {
                let v = values(tau);
                assert!(v.iter().all(|x| *x == v[0]), "one τ per evaluation for the whole batch");
                taus.push(v[0] as f64);
                Tensor::zeros([b, p, t * c], &d)
            },
            &cond,
            Tensor::zeros([b, p, t, c], &d),
            &opts,
        );
        assert_eq!(taus, expected, "{solver:?}");
    }
    // The embedder sees raw τ: at τ = 0 the sinusoid is [cos 0 = 1 ‖ sin 0 = 0], at τ = 1 it is not.
    let emb = values(timestep_sinusoid(Tensor::from_floats([0.0, 1.0], &d)));
    assert!(emb[..TIME_FREQS].iter().all(|x| *x == 1.0));
    assert!(emb[TIME_FREQS..2 * TIME_FREQS].iter().all(|x| *x == 0.0));
    assert!(
        (emb[2 * TIME_FREQS] - 1f32.cos()).abs() < 1e-6,
        "first frequency is exp(0) = 1"
    );
}

// ----------------------------------------------------------------------------------------------------------------
// Layout (docs/method.md §4.1)

#[test]
fn channel_counts_at_paper_size() {
    assert_eq!(
        MmditConfig::paper(KeyframeConditioning::InputMask, 768).in_channels(),
        221
    );
    assert_eq!(
        MmditConfig::paper(KeyframeConditioning::ImputeUntil, 768).in_channels(),
        221
    );
    assert_eq!(MmditConfig::paper(KeyframeConditioning::None, 768).in_channels(), 204);
    assert_eq!(
        MmditConfig::paper(KeyframeConditioning::ReplaceNoised, 768).in_channels(),
        204
    );
    assert_eq!(
        MmditConfig::paper(KeyframeConditioning::InputMask, 768).out_channels(),
        192
    );
}

#[test]
fn build_input_places_keyframes_state_and_mask() {
    let d = dev();
    let (b, p, t, c) = (1, 2, 3, 2);
    let z0 = Tensor::<3>::full([b, p, c], 7.0, &d);
    let x = Tensor::<4>::full([b, p, t, c], -1.0, &d);
    let z_key = Tensor::<4>::full([b, p, t, c], 5.0, &d);
    let mask = Tensor::from_data(TensorData::new(vec![1f32, 0.0, 1.0], [b, t]), &d);
    let input = build_input(
        z0.clone(),
        x.clone(),
        mask.clone(),
        z_key.clone(),
        KeyframeConditioning::InputMask,
    );
    assert_eq!(input.dims(), [b, p, (t + 1) * (c + 1)]);
    // slot-major [z_s(2) ‖ m̂_s(1)]: shape slot, key (m=1), state (m=0), key (m=1); m̂ = [0; m]
    let row: Vec<f32> = values(input.clone().narrow(1, 0, 1));
    assert_eq!(row, vec![7.0, 7.0, 0.0, 5.0, 5.0, 1.0, -1.0, -1.0, 0.0, 5.0, 5.0, 1.0]);
    // Without mask channels: 204-style layout, no replacement for None.
    let plain = build_input(
        z0.clone(),
        x.clone(),
        mask.clone(),
        z_key.clone(),
        KeyframeConditioning::None,
    );
    assert_eq!(
        values(plain.narrow(1, 0, 1)),
        vec![7.0, 7.0, -1.0, -1.0, -1.0, -1.0, -1.0, -1.0]
    );
    let replaced = build_input(z0, x, mask, z_key, KeyframeConditioning::ReplaceNoised);
    assert_eq!(
        values(replaced.narrow(1, 0, 1)),
        vec![7.0, 7.0, 5.0, 5.0, -1.0, -1.0, 5.0, 5.0]
    );
}

#[test]
fn split_output_inverts_merge_slots() {
    let _g = lock();
    let d = dev();
    let x = normal([2, 3, 4, 5], &d);
    let round = split_output(merge_slots(x.clone()), 4);
    assert_eq!(values(round), values(x.clone()));
    // slot-major: channel f·C + k of the output is frame f, channel k
    let flat = values(merge_slots(x.clone()));
    let split = values(x);
    assert_eq!(flat[2 * 5 + 3], split[2 * 5 + 3]);
}

// ----------------------------------------------------------------------------------------------------------------
// Backbone

fn tiny_inputs(
    cfg: &MmditConfig,
    b: usize,
    p: usize,
    l: usize,
    d: &Device,
) -> (Tensor<3>, Tensor<3>, Tensor<1>, Tensor<1>) {
    (
        normal([b, p, cfg.in_channels()], d),
        normal([b, l, cfg.text_dim], d),
        Tensor::ones([b], d),
        Tensor::random([b], Distribution::Uniform(0.0, 1.0), d),
    )
}

#[test]
fn forward_shapes_and_zero_velocity_at_init() {
    let _g = lock();
    let d = dev();
    let cfg = MmditConfig::tiny();
    let model = cfg.init(&d);
    let (input, text, keep, tau) = tiny_inputs(&cfg, 2, 7, 5, &d);
    let v = model.forward(input, text, keep, tau);
    assert_eq!(v.dims(), [2, 7, cfg.out_channels()]);
    assert!(
        values(v).iter().all(|x| *x == 0.0),
        "zero-initialised output projection gives v = 0"
    );
}

#[test]
fn seeded_init_and_forward_are_deterministic() {
    let _g = lock();
    let d = dev();
    let cfg = MmditConfig::tiny();
    let run = |seed: u64| {
        d.seed(seed);
        let model = cfg.init(&d);
        let (input, text, keep, tau) = tiny_inputs(&cfg, 1, 4, 3, &d);
        // The output layer is zero at init; compare a block's hidden state through the report of weights instead.
        let weights: Vec<f32> = param_values(&model);
        (weights, values(model.forward(input, text, keep, tau)))
    };
    let (w1, v1) = run(11);
    let (w2, v2) = run(11);
    let (w3, _) = run(12);
    assert_eq!(w1, w2);
    assert_eq!(v1, v2);
    assert_ne!(w1, w3, "another seed gives other weights");
}

/// All float parameters, flattened in visiting order.
fn param_values<M: Module>(m: &M) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.extend(values(param.val()));
        }
    }
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

fn tiny_batch(cfg: &MmditConfig, b: usize, p: usize, l: usize, d: &Device) -> RfBatch {
    let z = normal([b, p, cfg.frames, cfg.channels], d);
    RfBatch {
        z0: normal([b, p, cfg.channels], d),
        z_key: z.clone(),
        z,
        mask: first_last_mask(b, cfg.frames, d),
        text: normal([b, l, cfg.text_dim], d),
        keep_txt: Tensor::ones([b], d),
        scene: None,
    }
}

#[test]
fn every_parameter_gets_a_gradient_after_one_step() {
    // The zero-initialised output layer blocks every gradient but its own at step 0, so take one optimiser
    // step first; after it every parameter (all blocks, both adaLN streams, text and time paths) must get one.
    // Exception by design (AAM's CogX block): the text stream leaves the network after the last block's
    // attention, so that block's text-side post-attention LayerNorm never influences the output.
    let _g = lock();
    let d = dev().autodiff();
    let cfg = MmditConfig::tiny();
    let mut model = cfg.init(&d);
    let batch = tiny_batch(&cfg, 2, 6, 3, &d);
    let opts = RfLossOptions {
        conditioning: KeyframeConditioning::InputMask,
        keyframe_loss: KeyframeLoss::All,
        tau_star: 0.98,
    };
    let mut optim = AdamWConfig::new().init();
    let eps = normal(batch.z.dims(), &d);
    let tau = Tensor::from_floats([0.3, 0.7], &d);
    let loss = rf_training_loss(&model, &batch, eps.clone(), tau.clone(), &opts);
    let grads = GradientsParams::from_grads(loss.backward(), &model);
    model = optim.step(1e-2, model, grads);

    let loss = rf_training_loss(&model, &batch, eps, tau, &opts);
    let grads = loss.backward();
    struct Check<'a> {
        grads: &'a burn::tensor::Gradients,
        path: Vec<String>,
        missing: Vec<String>,
        total: usize,
    }
    impl ModuleVisitor for Check<'_> {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.total += 1;
            let nonzero = param
                .val()
                .grad(self.grads)
                .map(|g| values(g).iter().any(|x| *x != 0.0))
                .unwrap_or(false);
            if !nonzero {
                self.missing.push(self.path.join("."));
            }
        }
    }
    let mut check = Check {
        grads: &grads,
        path: Vec::new(),
        missing: Vec::new(),
        total: 0,
    };
    model.visit(&mut check);
    assert!(check.total > 30, "visited {} parameters", check.total);
    let last = cfg.blocks - 1;
    let dead = [
        format!("blocks.{last}.norm2_text.beta"),
        format!("blocks.{last}.norm2_text.gamma"),
    ];
    let mut missing = check.missing.clone();
    missing.sort();
    assert_eq!(missing, dead.to_vec(), "parameters without gradient");
}

#[test]
fn cfg_with_unit_guidance_equals_the_conditional_branch() {
    let _g = lock();
    let d = dev();
    let cfg = MmditConfig::tiny();
    let model = trained_one_step(&cfg, &d);
    let (input, text, _, tau) = tiny_inputs(&cfg, 2, 5, 3, &d);
    let v_cond = model.forward(input.clone(), text.clone(), Tensor::ones([2], &d), tau.clone());
    let v_uncond = model.forward(input.clone(), text.clone(), Tensor::zeros([2], &d), tau.clone());
    assert!(
        max_abs_diff(v_cond.clone(), v_uncond.clone()) > 1e-6,
        "text must matter after a step"
    );
    assert!(max_abs_diff(cfg_combine(v_cond.clone(), v_uncond.clone(), 1.0), v_cond.clone()) < 1e-6);
    assert!(max_abs_diff(cfg_combine(v_cond.clone(), v_uncond.clone(), 0.0), v_uncond.clone()) < 1e-6);
    let mut w1 = mmdit_velocity(&model, text.clone(), Tensor::ones([2], &d), 1.0, None);
    assert!(max_abs_diff(w1(input.clone(), tau.clone()), v_cond.clone()) < 1e-5);
    let mut w3 = mmdit_velocity(&model, text, Tensor::ones([2], &d), 3.0, None);
    let expect = v_uncond.clone() + (v_cond - v_uncond).mul_scalar(3.0);
    assert!(
        max_abs_diff(w3(input, tau), expect) < 1e-4,
        "batched CFG branches match separate calls"
    );
}

/// A tiny model after one AdamW step (non-zero output layer), back on the plain device.
fn trained_one_step(cfg: &MmditConfig, d: &Device) -> Mmdit {
    let ad = d.clone().autodiff();
    let model = cfg.init(&ad);
    let batch = tiny_batch(cfg, 2, 6, 3, &ad);
    let opts = RfLossOptions {
        conditioning: cfg.conditioning,
        keyframe_loss: KeyframeLoss::All,
        tau_star: 0.98,
    };
    let eps = normal(batch.z.dims(), &ad);
    let loss = rf_training_loss(&model, &batch, eps, Tensor::from_floats([0.2, 0.9], &ad), &opts);
    let grads = GradientsParams::from_grads(loss.backward(), &model);
    AdamWConfig::new().init().step(1e-2, model, grads).valid()
}

#[test]
fn tiny_rf_overfits_one_batch() {
    let _g = lock();
    let d0 = dev();
    d0.seed(5);
    let d = d0.autodiff();
    let cfg = MmditConfig::tiny();
    let mut model = cfg.init(&d);
    let batch = tiny_batch(&cfg, 2, 8, 3, &d);
    let eps = normal(batch.z.dims(), &d);
    let tau = Tensor::from_floats([0.35, 0.65], &d);
    let opts = RfLossOptions {
        conditioning: KeyframeConditioning::InputMask,
        keyframe_loss: KeyframeLoss::All,
        tau_star: 0.98,
    };
    let mut optim = AdamWConfig::new().with_beta_2(0.99).init();
    let mut losses = Vec::new();
    for _ in 0..150 {
        let loss = rf_training_loss(&model, &batch, eps.clone(), tau.clone(), &opts);
        losses.push(values(loss.clone())[0]);
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optim.step(3e-3, model, grads);
    }
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(last * 10.0 <= first, "loss {first} → {last} did not fall 10×");
}

/// docs/method.md §4.9: a data-predicting network's loss is (R5) on the velocity (R10) its output implies, with the
/// un-replaced interpolant and 1 − τ floored at 0.05 (τ = 1 is drawn here); a velocity network's output is used as
/// it is.
#[test]
fn a_data_predicting_network_is_trained_on_its_implied_velocity() {
    let _g = lock();
    let d = dev();
    let opts = RfLossOptions {
        conditioning: KeyframeConditioning::InputMask,
        keyframe_loss: KeyframeLoss::All,
        tau_star: 0.98,
    };
    for prediction in [Prediction::Velocity, Prediction::Data] {
        let cfg = MmditConfig {
            prediction,
            ..MmditConfig::tiny()
        };
        let model = trained_one_step(&cfg, &d);
        assert_eq!(model.prediction(), prediction);
        let batch = tiny_batch(&cfg, 2, 5, 3, &d);
        let eps = normal(batch.z.dims(), &d);
        let tau = Tensor::<1>::from_floats([0.4, 1.0], &d);
        let loss = values(rf_training_loss(&model, &batch, eps.clone(), tau.clone(), &opts))[0];
        let x_tau = interpolant(eps.clone(), batch.z.clone(), tau.clone());
        let input = build_input(
            batch.z0.clone(),
            x_tau.clone(),
            batch.mask.clone(),
            batch.z_key.clone(),
            KeyframeConditioning::InputMask,
        );
        let out = split_output(
            model.forward(input, batch.text.clone(), batch.keep_txt.clone(), tau.clone()),
            cfg.frames,
        );
        let v = match prediction {
            Prediction::Velocity => out,
            Prediction::Data => {
                let gap = Tensor::<1>::from_floats([0.6, DATA_PREDICTION_MIN_GAP as f32], &d).reshape([2, 1, 1, 1]);
                (out - x_tau) / gap
            }
        };
        let want = values((v - target_velocity(eps, batch.z.clone())).square().mean())[0];
        assert!(
            (loss - want).abs() <= 1e-5 * want.abs().max(1.0),
            "{prediction:?}: {loss} vs {want}"
        );
    }
}

// ----------------------------------------------------------------------------------------------------------------
// Loss options, τ samplers

#[test]
fn loss_on_non_keyframes_ignores_keyframe_slots() {
    let d = dev();
    let (b, p, t, c) = (1, 2, 3, 2);
    let target = Tensor::<4>::zeros([b, p, t, c], &d);
    // error 1 on frame 0 (keyframe), 3 on frame 1, 0 on frame 2
    let mut pred = vec![0f32; b * p * t * c];
    for pi in 0..p {
        for k in 0..c {
            pred[(pi * t) * c + k] = 1.0;
            pred[(pi * t + 1) * c + k] = 3.0;
        }
    }
    let pred = Tensor::from_data(TensorData::new(pred, [b, p, t, c]), &d);
    let mask = Tensor::from_data(TensorData::new(vec![1f32, 0.0, 0.0], [b, t]), &d);
    let all = values(rf_loss(pred.clone(), target.clone(), mask.clone(), KeyframeLoss::All))[0];
    let non = values(rf_loss(pred, target, mask, KeyframeLoss::NonKeyframesOnly))[0];
    assert!((all - (1.0 + 9.0) / 3.0).abs() < 1e-6, "all slots: {all}");
    assert!((non - 9.0 / 2.0).abs() < 1e-6, "non-keyframe slots: {non}");
}

#[test]
fn cosmap_is_symmetric_and_maps_the_ends() {
    let d = dev();
    let u = Tensor::from_floats([0.0, 0.25, 0.5, 0.75, 1.0], &d);
    let v = values(TauSampler::Cosmap.map(u.clone()));
    assert!(v[0].abs() < 1e-7 && (v[4] - 1.0).abs() < 1e-6 && (v[2] - 0.5).abs() < 1e-6);
    assert!((v[1] + v[3] - 1.0).abs() < 1e-6, "cosmap(u) + cosmap(1 − u) = 1");
    assert_eq!(values(TauSampler::Uniform.map(u.clone())), values(u));
}

/// The logit-normal τ sampler (SD3): the normal quantile at known points, τ = sigmoid(mean) at u = 1/2, draws in
/// (0, 1) whose logits have the configured mean and spread, and bad parameters refused.
#[test]
fn logit_normal_tau_follows_its_mean_and_spread() {
    let _g = lock();
    for (p, z) in [
        (0.5, 0.0),
        (0.975, 1.959_963_985),
        (0.001, -3.090_232_306),
        (0.9999, 3.719_016_485),
    ] {
        assert!(
            (normal_quantile(p) - z).abs() < 1e-6,
            "Φ⁻¹({p}) = {} not {z}",
            normal_quantile(p)
        );
    }
    let sampler = TauSampler::LogitNormal { mean: -0.8, std: 0.8 };
    let d = dev();
    let mid = values(sampler.map(Tensor::from_floats([0.5, 0.975], &d)));
    let sigmoid = |x: f64| 1.0 / (1.0 + (-x).exp());
    assert!((f64::from(mid[0]) - sigmoid(-0.8)).abs() < 1e-6);
    assert!((f64::from(mid[1]) - sigmoid(-0.8 + 0.8 * 1.959_963_985)).abs() < 1e-6);
    d.seed(3);
    let taus = values(sampler.sample(4000, &d));
    assert!(taus.iter().all(|&t| t > 0.0 && t < 1.0));
    let logits: Vec<f64> = taus
        .iter()
        .map(|&t| (f64::from(t) / (1.0 - f64::from(t))).ln())
        .collect();
    let mean = logits.iter().sum::<f64>() / logits.len() as f64;
    let sd = (logits.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / logits.len() as f64).sqrt();
    assert!(
        (mean + 0.8).abs() < 0.05 && (sd - 0.8).abs() < 0.05,
        "logit mean {mean}, std {sd}"
    );
    assert!(TauSampler::LogitNormal { mean: 0.0, std: 0.0 }.validate().is_err());
    assert!(
        TauSampler::LogitNormal {
            mean: f64::NAN,
            std: 1.0
        }
        .validate()
        .is_err()
    );
    assert!(sampler.validate().is_ok() && TauSampler::Uniform.validate().is_ok());
}

#[test]
fn impute_until_stops_replacing_after_tau_star() {
    let _g = lock();
    let d = dev();
    let (b, p, t, c) = (1, 2, 2, 2);
    let z_key = Tensor::<4>::full([b, p, t, c], 9.0, &d);
    let cond = Conditioning {
        z0: Tensor::zeros([b, p, c], &d),
        z_key,
        mask: Tensor::ones([b, t], &d),
        scene: None,
    };
    let opts = SampleOptions {
        n_grid: 5,
        solver: Solver::Euler,
        tau_star: 0.5,
        ..SampleOptions::paper(KeyframeConditioning::ImputeUntil)
    };
    let mut seen = Vec::new();
    sample(
        |input: Tensor<3>, tau: Tensor<1>| {
            let row = values(input.narrow(1, 0, 1));
            // slot 1 latent at channels [3, 5), its mask channel at 5
            seen.push((values(tau)[0], row[3], row[5]));
            Tensor::zeros([b, p, t * c], &d)
        },
        &cond,
        Tensor::zeros([b, p, t, c], &d),
        &opts,
    );
    assert_eq!(
        seen,
        vec![(0.0, 9.0, 1.0), (0.25, 9.0, 1.0), (0.5, 0.0, 1.0), (0.75, 0.0, 1.0)]
    );
}

#[test]
fn param_report_sums_to_num_params() {
    let d = dev();
    let model = MmditConfig::tiny().init(&d);
    let report = param_report(&model);
    let (name, total) = report.last().unwrap();
    assert_eq!(name, "total");
    assert_eq!(*total, model.num_params());
    assert!(report.iter().any(|(n, c)| n == "blocks" && *c > 0));
}

#[test]
#[ignore = "paper-size init, a few seconds; run with: cargo test -p any4d-model --test rf -- --ignored"]
fn paper_size_parameter_count() {
    let model = MmditConfig::paper(KeyframeConditioning::InputMask, 768).init(&dev());
    assert_eq!(model.num_params(), 78_359_744);
}

#[test]
#[ignore = "paper-size timing, about a minute on 2 cores; `any4d bench model` prints the same numbers"]
fn paper_size_step_timing() {
    let cfg = MmditConfig::paper(KeyframeConditioning::InputMask, 768);
    let t = any4d_model::bench::time_rf_step(&cfg, 1, 512, 77, 2, &dev());
    println!(
        "RF forward+backward, paper size, batch 1, flex: {:.1} ms/clip ({:?})",
        t.median_ms, t.steps_ms
    );
    assert!(t.median_ms > 0.0);
}
