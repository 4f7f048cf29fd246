//! The keyframe-interpolation anchor of the flow (docs/method.md §4.10): the interpolation itself, the sampler's lift
//! from residual to latents, the training target and the config checks.

use any4d_model::anchor::keyframe_lerp;
use any4d_model::mmdit::{Anchor, KeyframeConditioning, MmditConfig, Prediction, build_input, merge_slots};
use any4d_model::rectified_flow::{
    Conditioning, KeyframeLoss, RfBatch, RfLossOptions, SampleOptions, rf_loss, rf_training_loss, sample_outputs,
    target_velocity,
};
use burn::prelude::*;
use burn::tensor::{Distribution, TensorData};

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

fn mask(rows: &[&[usize]], t: usize, device: &Device) -> Tensor<2> {
    let mut m = vec![0f32; rows.len() * t];
    for (i, keys) in rows.iter().enumerate() {
        for &f in *keys {
            m[i * t + f] = 1.0;
        }
    }
    Tensor::from_data(TensorData::new(m, [rows.len(), t]), device)
}

#[test]
fn keyframe_lerp_follows_the_line_between_keyframes_holds_beyond_them_and_is_zero_without_any() {
    let d = Device::flex();
    let t = 7;
    // One token, one channel: Z_f = f² + 1 in window 0, anything in window 1 (it has no keyframes).
    let z: Vec<f32> = (0..2 * t).map(|i| ((i % t) * (i % t)) as f32 + 1.0).collect();
    let z = Tensor::<4>::from_data(TensorData::new(z, [2, 1, t, 1]), &d);
    let a = values(keyframe_lerp(z, mask(&[&[1, 4, 5], &[]], t, &d)));
    let (z1, z4, z5) = (2.0f32, 17.0, 26.0);
    let want = [z1, z1, z1 + (z4 - z1) / 3.0, z1 + 2.0 * (z4 - z1) / 3.0, z4, z5, z5];
    for (f, (&got, &w)) in a[..t].iter().zip(&want).enumerate() {
        assert!((got - w).abs() < 1e-5, "frame {f}: {got} != {w}");
    }
    assert!(a[t..].iter().all(|&x| x == 0.0), "no keyframes: {:?}", &a[t..]);
}

/// A network that outputs the clean scaled residual (Z − A)/s ends, with the anchor, on Z (keyframes replaced by
/// Z_key); and at τ = 0 it sees the state lifted to latents, A + s ε.
#[test]
fn an_anchored_sampler_lifts_the_residual_to_latents_for_the_network_and_at_the_end() {
    let d = Device::flex();
    let (b, p, t, c) = (2, 3, 5, 2);
    let scale = 0.5;
    let z = normal([b, p, t, c], &d);
    let m = mask(&[&[0, 4], &[0, 2, 4]], t, &d);
    let a = keyframe_lerp(z.clone(), m.clone());
    let residual = (z.clone() - a.clone()).div_scalar(scale);
    let cond = Conditioning {
        z0: normal([b, p, c], &d),
        z_key: z.clone(),
        mask: m.clone(),
        scene: None,
    };
    let eps = normal([b, p, t, c], &d);
    let opts = SampleOptions::paper(KeyframeConditioning::InputMask);
    let mut first_input = None;
    let oracle = merge_slots(residual.clone());
    let out = sample_outputs(
        |input: Tensor<3>, _tau| {
            first_input.get_or_insert(input);
            oracle.clone()
        },
        Prediction::Data,
        Anchor::KeyframeLerp { scale },
        &cond,
        eps.clone(),
        &opts,
    );
    assert!(max_abs_diff(out, z.clone()) < 1e-4, "the sample is not Z");
    let lifted = a + eps.mul_scalar(scale);
    let want = build_input(cond.z0.clone(), lifted, m, z, KeyframeConditioning::InputMask);
    let got = first_input.expect("the network was called");
    assert!(
        max_abs_diff(got, want) < 1e-5,
        "the network did not see A + s ε at τ = 0"
    );
}

/// With the anchor the flow's data end is (Z − A)/s: at initialisation (zero output layer) the loss is (R5) of a zero
/// velocity against (Z − A)/s − ε, which differs from the paper's target Z − ε.
#[test]
fn anchored_training_targets_the_scaled_residual() {
    let d = Device::flex().autodiff();
    let scale = 0.25;
    let cfg = MmditConfig {
        anchor: Anchor::KeyframeLerp { scale },
        ..MmditConfig::tiny()
    };
    let model = cfg.init(&d);
    let (b, p, t, c) = (2, 3, cfg.frames, cfg.channels);
    let z = normal([b, p, t, c], &d);
    let m = mask(&[&[0, t - 1], &[0, 1, t - 1]], t, &d);
    let batch = RfBatch {
        z0: normal([b, p, c], &d),
        z: z.clone(),
        z_key: z.clone(),
        mask: m.clone(),
        text: normal([b, 2, cfg.text_dim], &d),
        keep_txt: Tensor::ones([b], &d),
        scene: None,
    };
    let opts = RfLossOptions {
        conditioning: KeyframeConditioning::InputMask,
        keyframe_loss: KeyframeLoss::All,
        tau_star: 0.98,
    };
    let eps = normal([b, p, t, c], &d);
    let loss = values(rf_training_loss(
        &model,
        &batch,
        eps.clone(),
        Tensor::from_floats([0.3, 0.8], &d),
        &opts,
    ))[0];
    let x1 = (z.clone() - keyframe_lerp(z.clone(), m.clone())).div_scalar(scale);
    let zero = eps.zeros_like();
    let want = values(rf_loss(
        zero.clone(),
        target_velocity(eps.clone(), x1),
        m.clone(),
        KeyframeLoss::All,
    ))[0];
    let paper = values(rf_loss(zero, target_velocity(eps, z), m, KeyframeLoss::All))[0];
    assert!((loss - want).abs() < 1e-4 * want, "loss {loss} != {want}");
    assert!(
        (loss - paper).abs() > 1e-2 * paper,
        "the anchor changed nothing ({loss} vs {paper})"
    );
}

#[test]
fn an_anchor_needs_a_positive_scale_and_the_input_mask() {
    for scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let cfg = MmditConfig {
            anchor: Anchor::KeyframeLerp { scale },
            ..MmditConfig::tiny()
        };
        let err = cfg.validate().expect_err("a bad scale must be refused");
        assert!(err.contains("scale"), "{err}");
    }
    let cfg = MmditConfig {
        anchor: Anchor::KeyframeLerp { scale: 0.5 },
        conditioning: KeyframeConditioning::ReplaceNoised,
        ..MmditConfig::tiny()
    };
    let err = cfg.validate().expect_err("the anchor needs the clean keyframes");
    assert!(err.contains("input_mask"), "{err}");
}
