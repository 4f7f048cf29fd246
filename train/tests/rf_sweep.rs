//! Every combination of the RF's switches on the tiny preset (`configs/rf/tiny.toml`, with few tokens): keyframe
//! conditioning × ODE solver × τ sampler × keyframe loss × replacement noise gives a finite (R5) loss and samples
//! of the right shape whose keyframe slots hold the keyframe latents where the sampler clamps them
//! (docs/method.md §4.2, §4.6, §5.1, §5.4).

use std::path::Path;

use any4d_model::mmdit::KeyframeConditioning;
use any4d_model::rectified_flow::{
    Conditioning, KeyframeLoss, ReplaceNoise, RfBatch, RfLossOptions, SampleOptions, Solver, TauSampler,
    rf_training_loss, sample_mmdit,
};
use any4d_train::rf_loop::{RfRunConfig, training_mask};
use burn::prelude::{Device, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const CONDITIONINGS: [KeyframeConditioning; 4] = [
    KeyframeConditioning::InputMask,
    KeyframeConditioning::ReplaceNoised,
    KeyframeConditioning::ImputeUntil,
    KeyframeConditioning::None,
];
const SOLVERS: [Solver; 2] = [Solver::Euler, Solver::Midpoint];
const TAU_SAMPLERS: [TauSampler; 2] = [TauSampler::Uniform, TauSampler::Cosmap];
const KEYFRAME_LOSSES: [KeyframeLoss; 2] = [KeyframeLoss::All, KeyframeLoss::NonKeyframesOnly];
const REPLACE_NOISES: [ReplaceNoise; 2] = [ReplaceNoise::Fixed, ReplaceNoise::Fresh];

/// Batch, tokens and text tokens of the sweep: tiny, so 64 combinations take seconds.
const B: usize = 2;
const P: usize = 3;
const L: usize = 4;

fn tiny() -> RfRunConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/rf/tiny.toml");
    RfRunConfig::load(&path, &[]).expect("configs/rf/tiny.toml")
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 data")
}

#[test]
fn every_combination_of_the_rf_switches_trains_and_samples() {
    let base = tiny();
    let (t, c) = (base.model.frames, base.model.channels);
    let device = Device::flex();
    let mut combinations = 0;
    for conditioning in CONDITIONINGS {
        let mut cfg = base.clone();
        cfg.model.conditioning = conditioning;
        device.seed(7);
        let model = cfg.model.init(&device);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // One keyframe mask per sample from the preset's sampler; modes trained without keyframes get none, so give
        // the sampler first and last frames there (the replacement baseline is sampled with keyframes).
        let mut mask: Vec<f32> = (0..B)
            .flat_map(|_| training_mask(&cfg.rf, conditioning, t, &mut rng))
            .map(|m| f32::from(u8::from(m)))
            .collect();
        for b in 0..B {
            (mask[b * t], mask[b * t + t - 1]) = (1.0, 1.0);
        }
        let mask = Tensor::<2>::from_data(TensorData::new(mask, [B, t]), &device);
        let normal = Distribution::Normal(0.0, 1.0);
        let z0 = Tensor::<3>::random([B, P, c], normal, &device);
        let z = Tensor::<4>::random([B, P, t, c], normal, &device);
        let text = Tensor::<3>::random([B, L, cfg.model.text_dim], normal, &device);
        for tau_sampler in TAU_SAMPLERS {
            for keyframe_loss in KEYFRAME_LOSSES {
                let batch = RfBatch {
                    z0: z0.clone(),
                    z: z.clone(),
                    z_key: z.clone(),
                    mask: mask.clone(),
                    text: text.clone(),
                    keep_txt: Tensor::ones([B], &device),
                    scene: None,
                };
                let options = RfLossOptions {
                    conditioning,
                    keyframe_loss,
                    tau_star: cfg.rf.tau_star,
                };
                let eps = Tensor::random([B, P, t, c], normal, &device);
                let tau = tau_sampler.sample(B, &device);
                let loss = rf_training_loss(&model, &batch, eps, tau, &options); // (R5)
                assert_eq!(loss.dims(), [1]);
                let value = loss.into_scalar::<f32>();
                assert!(
                    value.is_finite() && value > 0.0,
                    "{conditioning:?} {tau_sampler:?} {keyframe_loss:?}: loss {value}"
                );
                for solver in SOLVERS {
                    for replace_noise in REPLACE_NOISES {
                        let opts = SampleOptions {
                            n_grid: 3,
                            solver,
                            conditioning,
                            replace_noise,
                            tau_star: cfg.rf.tau_star,
                            fresh_seed: 7,
                            noise_scale: 1.0,
                        };
                        let cond = Conditioning {
                            z0: z0.clone(),
                            z_key: z.clone(),
                            mask: mask.clone(),
                            scene: None,
                        };
                        let eps = Tensor::random([B, P, t, c], normal, &device);
                        let x = sample_mmdit(&model, &cond, text.clone(), Tensor::ones([B], &device), eps, 1.0, &opts);
                        let what = format!("{conditioning:?} {solver:?} {replace_noise:?}");
                        assert_eq!(x.dims(), [B, P, t, c], "{what}");
                        let values = floats(x.clone());
                        assert!(values.iter().all(|v| v.is_finite()), "{what}: non-finite sample");
                        // Keyframe slots are clamped to Z_key by the samplers that replace keyframes.
                        let clamped = matches!(
                            conditioning,
                            KeyframeConditioning::InputMask | KeyframeConditioning::ReplaceNoised
                        );
                        let first = floats(x.narrow(2, 0, 1));
                        let key = floats(z.clone().narrow(2, 0, 1));
                        let equal = first.iter().zip(&key).all(|(a, b)| (a - b).abs() < 1e-6);
                        assert_eq!(equal, clamped, "{what}: keyframe slot clamped = {equal}");
                        combinations += 1;
                    }
                }
            }
        }
    }
    assert_eq!(
        combinations,
        CONDITIONINGS.len() * SOLVERS.len() * TAU_SAMPLERS.len() * KEYFRAME_LOSSES.len() * REPLACE_NOISES.len()
    );
}
