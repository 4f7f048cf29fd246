//! Tests of the BD-LSTM baseline: chain shapes for both codecs, free-running steps, the shared weights of the two
//! chains, the losses (B1)–(B3) on hand-worked inputs, the mesh convolution (Qiao et al., Eq. 2) and the completion merge rule.
//! Tiny configs on `Device::flex()`; tests that draw from the device RNG share one lock (the seed is global).

use std::sync::{Mutex, MutexGuard};

use any4d_model::bdlstm::{
    BdLstm, BdLstmConfig, BdLstmLossConfig, BdLstmOutput, ChainOutput, FrameCodec, InitialStates, LatentCodec,
    LatentCodecConfig, MergeConfig, MeshConvCodecConfig, MeshGraph, Posterior, SegmentError, SegmentTry, bbox_diagonal,
    bdlstm_loss, frame_distance, l2_penalty, merge_segment,
};
use burn::module::{ModuleVisitor, Param};
use burn::prelude::*;
use burn::tensor::Distribution;

static RNG_LOCK: Mutex<()> = Mutex::new(());

fn lock() -> MutexGuard<'static, ()> {
    RNG_LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().expect("f32 data")
}

fn assert_close(a: &[f32], b: &[f32], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol, "{what}[{i}]: {x} vs {y}");
    }
}

fn latent_model(device: &Device) -> BdLstm<LatentCodec> {
    BdLstmConfig::new().init(LatentCodecConfig::tiny().init(device), device)
}

/// A `[B, n, 6, 4]` window of tiny latents.
fn window(b: usize, n: usize, device: &Device) -> Tensor<4> {
    Tensor::random([b, n, 6, 4], Distribution::Normal(0.0, 1.0), device)
}

#[test]
fn latent_chains_have_the_documented_shapes_and_start_at_the_endpoints() {
    let _g = lock();
    let device = Device::flex();
    device.seed(3);
    let model = latent_model(&device);
    let x = window(2, 5, &device);
    let out = model.forward(x.clone(), &model.initial_states(2, &device), &(), Posterior::Mean);
    assert_eq!(out.forward.frames.dims(), [2, 5, 6, 4]);
    assert_eq!(out.backward.frames.dims(), [2, 5, 6, 4]);
    assert_eq!(out.forward.mu.dims(), [2, 4, 8]);
    assert_eq!(out.backward.logvar.dims(), [2, 4, 8]);
    let first = |t: Tensor<4>, i: usize| floats(t.narrow(1, i, 1));
    assert_eq!(first(out.forward.frames.clone(), 0), first(x.clone(), 0), "S^f_1 = X_1");
    assert_eq!(first(out.backward.frames.clone(), 0), first(x, 4), "S^b_1 = X_n");
    let all = floats(out.forward.frames)
        .into_iter()
        .chain(floats(out.backward.frames));
    assert!(all.into_iter().all(f32::is_finite));
}

#[test]
fn chains_are_free_running_and_share_their_weights() {
    let _g = lock();
    let device = Device::flex();
    device.seed(4);
    let model = latent_model(&device);
    let x = window(1, 4, &device);
    let init = model.initial_states(1, &device);
    let out = model.forward(x.clone(), &init, &(), Posterior::Mean);

    // Free-running: step t's input is the chain's own output of step t − 1.
    let mut frame = x.clone().narrow(1, 0, 1).reshape([1, 6, 4]);
    let mut state = init.forward.clone();
    for t in 1..4 {
        let (next, _, _, s) = model.step(frame, state, &(), Posterior::Mean);
        let got = floats(out.forward.frames.clone().narrow(1, t, 1));
        assert_close(&floats(next.clone()), &got, 1e-6, &format!("forward step {t}"));
        (frame, state) = (next, s);
    }

    // One set of weights: the backward chain is the forward chain run on the reversed window from −s₀.
    let swapped = InitialStates {
        forward: init.backward.clone(),
        backward: init.forward.clone(),
    };
    let reversed = model.forward(x.flip([1]), &swapped, &(), Posterior::Mean);
    assert_close(
        &floats(out.backward.frames.clone()),
        &floats(reversed.forward.frames),
        1e-6,
        "backward chain vs forward chain on the reversed window",
    );
    let lstm_params: usize = 3 * 4 * 2 * (8 * 8 + 8);
    let codec_params = model.codec().num_params();
    assert_eq!(
        model.num_params(),
        codec_params + lstm_params,
        "one LSTM stack, not one per direction"
    );
}

#[test]
fn initial_states_are_opposite_and_retries_perturb_them() {
    let _g = lock();
    let device = Device::flex();
    device.seed(5);
    let model = latent_model(&device);
    let nominal = model.retry_states(0, 2, &device);
    assert_eq!(nominal.forward.layers.len(), 3);
    for (f, b) in nominal.forward.layers.iter().zip(&nominal.backward.layers) {
        assert!(floats(f.hidden.clone()).iter().all(|&v| (v - 0.1).abs() < 1e-7));
        assert!(floats(b.cell.clone()).iter().all(|&v| (v + 0.1).abs() < 1e-7));
    }
    let retry = model.retry_states(1, 2, &device);
    let (f, b) = (
        floats(retry.forward.layers[1].cell.clone()),
        floats(retry.backward.layers[1].cell.clone()),
    );
    assert!(f.iter().any(|&v| (v - 0.1).abs() > 1e-3), "a retry perturbs s₀");
    assert_close(
        &f,
        &b.iter().map(|v| -v).collect::<Vec<_>>(),
        0.0,
        "backward = −forward",
    );
}

fn tensor4(v: &[[f32; 2]], b: usize, n: usize, device: &Device) -> Tensor<4> {
    Tensor::<1>::from_floats(v.concat().as_slice(), device).reshape([b, n, 1, 2])
}

#[test]
fn losses_match_a_hand_worked_window() {
    let device = Device::flex();
    // n = 2 frames of one token with two channels: X_1 = (0, 0), X_2 = (3, 4).
    let x = tensor4(&[[0.0, 0.0], [3.0, 4.0]], 1, 2, &device);
    let chain = |frames: &[[f32; 2]], mu: f32| ChainOutput {
        frames: tensor4(frames, 1, 2, &device),
        mu: Tensor::full([1, 1, 2], mu, &device),
        logvar: Tensor::zeros([1, 1, 2], &device),
    };
    let out = BdLstmOutput {
        forward: chain(&[[0.0, 0.0], [3.0, 0.0]], 1.0),
        backward: chain(&[[3.0, 4.0], [0.0, 4.0]], 0.0),
    };
    let l2 = Tensor::<1>::from_floats([3.0], &device);
    let loss = bdlstm_loss(&out, x, l2, &BdLstmLossConfig::new());
    let one = |t: Tensor<1>| floats(t)[0];
    // (B1) 0 + ‖(3,0) − (3,4)‖ + 0 + ‖(0,4) − (0,0)‖ = 8; (B2) ‖X_1 − (0,4)‖ + ‖(3,0) − X_2‖ = 8.
    assert!(
        (one(loss.recon.clone()) - 8.0).abs() < 1e-4,
        "recon {}",
        one(loss.recon)
    );
    assert!(
        (one(loss.bidir.clone()) - 8.0).abs() < 1e-4,
        "bidir {}",
        one(loss.bidir)
    );
    // KL: forward μ = 1 on two dims → ½·2 = 1; backward μ = 0 → 0.
    assert!((one(loss.kl.clone()) - 1.0).abs() < 1e-6, "kl {}", one(loss.kl));
    // (B3) 8 + 0.5·8 + 0.1·1 + 0.1·3.
    assert!(
        (one(loss.total.clone()) - 12.4).abs() < 1e-4,
        "total {}",
        one(loss.total)
    );
}

#[test]
fn l2_penalty_sums_every_squared_parameter_and_carries_gradients() {
    let device = Device::flex().autodiff();
    let codec = LatentCodecConfig::tiny().init(&device);
    struct Sum(f64);
    impl ModuleVisitor for Sum {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0 += floats(p.val()).iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
        }
    }
    let mut want = Sum(0.0);
    codec.visit(&mut want);
    let got = l2_penalty(&codec, &device);
    assert!(
        (floats(got.clone())[0] as f64 - want.0).abs() < 1e-3 * want.0,
        "{:?} vs {}",
        floats(got),
        want.0
    );
}

#[test]
fn the_bidirectional_loss_trains_the_one_shared_cell() {
    let _g = lock();
    let device = Device::flex().autodiff();
    device.seed(6);
    let model = BdLstmConfig::new().init(LatentCodecConfig::tiny().init(&device), &device);
    let x = window(2, 4, &device);
    let out = model.forward(x.clone(), &model.initial_states(2, &device), &(), Posterior::Sample);
    // Only the backward chain's frames: still reaches every LSTM layer, so the chains use the same parameters.
    let grads = out.backward.frames.clone().sum().backward();
    struct Seen<'a>(&'a burn::tensor::Gradients, usize, usize);
    impl ModuleVisitor for Seen<'_> {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.1 += 1;
            if p.grad(self.0).is_some_and(|g| floats(g).iter().any(|&v| v != 0.0)) {
                self.2 += 1;
            }
        }
    }
    let mut seen = Seen(&grads, 0, 0);
    model.visit(&mut seen);
    assert_eq!(
        seen.1, seen.2,
        "every parameter gets a non-zero gradient from the backward chain alone"
    );
    let loss = bdlstm_loss(&out, x, l2_penalty(&model, &device), &BdLstmLossConfig::new());
    assert!(floats(loss.total).iter().all(|v| v.is_finite()));
}

#[test]
fn mesh_convolution_averages_the_one_ring() {
    let device = Device::flex();
    // Path 0–1–2 and an isolated vertex 3; duplicate and reversed edges are ignored.
    let graph = MeshGraph::new(&[[0, 1], [2, 1], [1, 0]], 4, &device).unwrap();
    let x = Tensor::<1>::from_floats([1.0, 10.0, 2.0, 20.0, 4.0, 40.0, 8.0, 80.0], &device).reshape([1, 4, 2]);
    let mean = floats(graph.neighbour_mean(x.clone()));
    assert_close(
        &mean,
        &[2.0, 20.0, 2.5, 25.0, 2.0, 20.0, 0.0, 0.0],
        1e-6,
        "neighbour mean",
    );
    // Two clips in a batch use the same graph.
    let two = Tensor::cat(vec![x.clone(), x.mul_scalar(2.0)], 0);
    assert_close(
        &floats(graph.neighbour_mean(two).narrow(0, 1, 1)),
        &mean.iter().map(|v| 2.0 * v).collect::<Vec<_>>(),
        1e-6,
        "batch",
    );
    assert!(MeshGraph::new(&[[0, 4]], 4, &device).is_err());
    assert!(MeshGraph::new(&[[2, 2]], 4, &device).is_err());
}

#[test]
fn acap_variant_runs_on_a_mesh_graph() {
    let _g = lock();
    let device = Device::flex();
    device.seed(7);
    let graph = MeshGraph::new(&[[0, 1], [1, 2], [2, 0], [2, 3], [3, 4]], 5, &device).unwrap();
    let codec = MeshConvCodecConfig::new(5).with_latent(6).init(&device);
    assert_eq!(codec.latent_width(), 6);
    let model = BdLstmConfig::new().init(codec, &device);
    let x = Tensor::<4>::random([2, 3, 5, 9], Distribution::Uniform(-0.95, 0.95), &device);
    let out = model.forward(x, &model.initial_states(2, &device), &graph, Posterior::Mean);
    assert_eq!(out.forward.frames.dims(), [2, 3, 5, 9]);
    assert_eq!(out.backward.frames.dims(), [2, 3, 5, 9]);
    assert_eq!(out.backward.mu.dims(), [2, 2, 6]);
    assert!(floats(out.backward.frames.clone()).iter().all(|v| v.is_finite()));
}

fn try_with(d: &[f64]) -> SegmentTry<usize> {
    let n = d.len();
    SegmentTry::new((0..n).collect(), (100..100 + n).collect(), d.to_vec()).unwrap()
}

#[test]
fn merge_rule_switches_chains_at_the_argmin() {
    let cfg = MergeConfig::new();
    let merged = merge_segment::<_, SegmentError>(&cfg, |_| Ok(try_with(&[0.3, 0.2, 0.01, 0.04, 0.5]))).unwrap();
    assert_eq!((merged.split, merged.tries, merged.accepted), (2, 1, true));
    assert_eq!(
        merged.frames,
        vec![0, 1, 2, 103, 104],
        "forward up to i*, backward after"
    );
    assert_eq!(merged.distance, 0.01);
    // Ties go to the earliest pair; NaN never wins.
    assert_eq!(try_with(&[f64::NAN, 0.2, 0.2]).best_pair(), (1, 0.2));
}

#[test]
fn merge_rule_retries_a_bounded_number_of_times_and_keeps_the_best() {
    let cfg = MergeConfig::new().with_max_tries(4);
    let mut calls = Vec::new();
    let d = [[0.5, 0.4, 0.6], [0.3, 0.2, 0.9], [0.7, 0.8, 0.25], [0.6, 0.6, 0.6]];
    let merged = merge_segment::<_, SegmentError>(&cfg, |k| {
        calls.push(k);
        Ok(try_with(&d[k]))
    })
    .unwrap();
    assert_eq!(calls, vec![0, 1, 2, 3], "never passes: exactly max_tries tries");
    assert_eq!(
        (merged.tries, merged.accepted, merged.split, merged.distance),
        (4, false, 1, 0.2)
    );
    // Passing on the third try stops there.
    let mut calls = 0;
    let merged = merge_segment::<_, SegmentError>(&cfg, |k| {
        calls += 1;
        Ok(try_with(if k == 2 { &[0.3, 0.01, 0.3] } else { &[0.3, 0.3, 0.3] }))
    })
    .unwrap();
    assert_eq!((calls, merged.tries, merged.accepted), (3, 3, true));
    let e = merge_segment::<usize, SegmentError>(&cfg.clone().with_max_tries(0), |_| unreachable!()).unwrap_err();
    assert_eq!(e, SegmentError::NoTries);
}

#[test]
fn segment_tries_and_distances_reject_bad_shapes() {
    assert!(matches!(
        SegmentTry::new(vec![1, 2, 3], vec![1, 2], vec![0.0; 3]),
        Err(SegmentError::Length { .. })
    ));
    assert!(matches!(
        SegmentTry::new(vec![1, 2], vec![1, 2], vec![0.0; 2]),
        Err(SegmentError::TooShort { .. })
    ));
    let a = [[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]];
    let b = [[0.0, 0.0, 1.0], [3.0, 4.0, 0.0]];
    assert!((bbox_diagonal(&a) - 5.0).abs() < 1e-12);
    // Mean distance (1 + 0) / 2 over a diagonal of 5.
    assert!((frame_distance(&a, &b, bbox_diagonal(&a)).unwrap() - 0.1).abs() < 1e-12);
    assert!(matches!(
        frame_distance(&a, &b[..1], 5.0),
        Err(SegmentError::Vertices { .. })
    ));
}
