//! Learned methods on the evaluation protocol (docs/method.md §4.6, §5.1, §5.2 latent lerp, §5.4, (E4)): shapes, seed
//! determinism, keyframe latents kept exactly, ground-truth keyframes after assembly, latent lerp, VAE rows. Tiny
//! untrained networks on `Device::flex()`; their zero-initialised layers are woken with noise so that every
//! network output depends on its input.

use std::sync::Arc;

use any4d_data::Clip;
use any4d_data::batch::PadTo;
use any4d_data::fps::farthest_point_sampling;
use any4d_data::preprocess::edges_from_faces;
use any4d_eval::learned::{
    LatentLerpSampler, LearnedModels, MeshCodec, RfSampler, VaeOracleSampler, VaeReconstructor, sampler_noise,
};
use any4d_eval::methods::{
    Method, MethodKind, Request, RfMethod, WindowSampler, complete_and_score, complete_and_score_batch,
    hide_non_keyframes,
};
use any4d_eval::tables::reconstruction::Reconstructor;
use any4d_model::any_vae::AnyMeshVae;
use any4d_model::dymesh_vae::DyMeshVaeConfig;
use any4d_model::frame_vae::FrameVaeConfig;
use any4d_model::latent_stats::LatentStats;
use any4d_model::mesh_vae::{EdgeList, Posterior, VaeBatch};
use any4d_model::mmdit::{KeyframeConditioning, MmditConfig};
use any4d_model::rectified_flow::{Conditioning, SampleOptions, sample_mmdit};
use any4d_model::text::{TextBatch, TextEncoder, TextError};
use burn::module::{ModuleMapper, Param};
use burn::prelude::*;
use burn::tensor::{Distribution, TensorData};

const T: usize = 4;
const P: usize = 16;
const C: usize = 4;
const SIDE: usize = 6;
const N: usize = SIDE * SIDE;

/// Replaces all-zero float parameters (zero-initialised output projections, biases) with N(0, 0.2²) noise.
struct WakeZeros;

impl ModuleMapper for WakeZeros {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.map(|t| {
            let peak = t.clone().abs().max().try_to_vec_as::<f32>().expect("f32")[0];
            if peak == 0.0 {
                t.random_like(Distribution::Normal(0.0, 0.2))
            } else {
                t
            }
        })
    }
}

/// A deterministic stand-in text encoder: per-token states from the caption bytes.
struct ByteText;

impl TextEncoder for ByteText {
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError> {
        let (l, d) = (self.max_len(), self.dim());
        let mut states = Vec::with_capacity(captions.len() * l * d);
        for caption in captions {
            let bytes = caption.as_bytes();
            for i in 0..l {
                let b = f32::from(bytes.get(i).copied().unwrap_or(0));
                states.extend((0..d).map(|j| (b * 0.1 + j as f32).sin()));
            }
        }
        Ok(TextBatch {
            states: Tensor::from_data(TensorData::new(states, [captions.len(), l, d]), device),
            pad_mask: Tensor::from_data(
                TensorData::new(vec![false; captions.len() * l], [captions.len(), l]),
                device,
            ),
        })
    }
    fn dim(&self) -> usize {
        8
    }
    fn max_len(&self) -> usize {
        5
    }
}

/// A T-frame waving grid of SIDE² vertices, two triangles per cell, roughly in [−1, 1]³.
fn wave_clip() -> Clip {
    let mut vertices = Vec::with_capacity(T * N);
    for f in 0..T {
        let phase = f as f32 * 0.7;
        for i in 0..SIDE {
            for j in 0..SIDE {
                let (x, y) = (i as f32 / 2.5 - 1.0, j as f32 / 2.5 - 1.0);
                vertices.push([x + 0.05 * f as f32, y, 0.3 * (2.0 * x + phase).sin() * (y + 0.5)]);
            }
        }
    }
    let mut faces = Vec::new();
    for i in 0..SIDE - 1 {
        for j in 0..SIDE - 1 {
            let v = (i * SIDE + j) as u32;
            let s = SIDE as u32;
            faces.push([v, v + 1, v + s]);
            faces.push([v + 1, v + s + 1, v + s]);
        }
    }
    Clip::new("grid_offset0_0-4", vertices, T, N, faces, "a waving flag", "test").expect("valid clip")
}

fn stats() -> LatentStats {
    LatentStats {
        shape_mean: 0.1,
        shape_std: 1.5,
        motion_mean: -0.2,
        motion_std: 0.7,
    }
}

fn frame_codec(device: &Device, padding: PadTo) -> Arc<MeshCodec> {
    let vae = FrameVaeConfig::tiny().init(device).map(&mut WakeZeros);
    Arc::new(MeshCodec::new(AnyMeshVae::Framewise(vae), P, padding, device.clone()).expect("codec"))
}

fn models(codec: Arc<MeshCodec>, net_mode: KeyframeConditioning, device: &Device) -> Arc<LearnedModels> {
    let cfg = MmditConfig {
        frames: T,
        channels: C,
        conditioning: net_mode,
        ..MmditConfig::tiny()
    };
    let rf = cfg.init(device).map(&mut WakeZeros);
    Arc::new(LearnedModels::new(codec, rf, cfg, stats(), Box::new(ByteText)).expect("models"))
}

fn options(conditioning: KeyframeConditioning) -> SampleOptions {
    SampleOptions {
        n_grid: 4,
        ..SampleOptions::paper(conditioning)
    }
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.try_to_vec_as::<f32>().expect("f32 tensor")
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn rows_diff(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    max_diff(&a.concat(), &b.concat())
}

/// Slot `f` of a `[1, T, P, C]` tensor.
fn slot(z: &[f32], f: usize) -> &[f32] {
    &z[f * P * C..(f + 1) * P * C]
}

#[test]
fn rf_sampler_gives_t_times_n_rows_deterministic_per_seed() {
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::InputMask,
        &device,
    );
    let sampler = RfSampler::new(m, options(KeyframeConditioning::InputMask), 1.0).unwrap();
    let gt = wave_clip();
    let keys = [0, 2, 3];
    let visible = hide_non_keyframes(&gt, &keys);
    let a = sampler.sample(&visible, &keys, "a waving flag", 42).unwrap();
    assert_eq!(a.len(), T * N);
    assert!(a.iter().flatten().all(|v| v.is_finite()));
    let again = sampler.sample(&visible, &keys, "a waving flag", 42).unwrap();
    assert_eq!(a, again, "same seed, same output");
    let other = sampler.sample(&visible, &keys, "a waving flag", 43).unwrap();
    assert!(
        rows_diff(&a[N..2 * N], &other[N..2 * N]) > 1e-4,
        "another seed changes the non-keyframe"
    );
    let full = sampler.sample(&gt, &keys, "a waving flag", 42).unwrap();
    assert_eq!(a, full, "only frame 0 and the keyframes are read");
    let caption = sampler.sample(&visible, &keys, "a jumping frog", 42).unwrap();
    assert!(
        rows_diff(&a[N..2 * N], &caption[N..2 * N]) > 1e-6,
        "the caption reaches the network"
    );
}

#[test]
fn a_batch_of_requests_samples_what_each_request_samples_alone() {
    let device = Device::flex();
    for (net, mode) in [
        (KeyframeConditioning::InputMask, KeyframeConditioning::InputMask),
        (KeyframeConditioning::ReplaceNoised, KeyframeConditioning::ReplaceNoised),
    ] {
        let m = models(frame_codec(&device, PadTo::BatchMax), net, &device);
        let sampler = RfSampler::new(m, options(mode), 1.0).unwrap();
        let gt = wave_clip();
        let (k1, k2) = ([0usize, 3], [0usize, 1, 3]);
        let (v1, v2) = (hide_non_keyframes(&gt, &k1), hide_non_keyframes(&gt, &k2));
        let requests = [
            Request {
                clip: &v1,
                keyframes: &k1,
                seed: 5,
                scene: None,
            },
            Request {
                clip: &v2,
                keyframes: &k2,
                seed: 6,
                scene: None,
            },
            Request {
                clip: &v1,
                keyframes: &k1,
                seed: 7,
                scene: None,
            },
        ];
        let batch = sampler.sample_batch(&requests, "a waving flag").unwrap();
        assert_eq!(batch.len(), 3);
        for (r, got) in requests.iter().zip(&batch) {
            let alone = sampler.sample(r.clip, r.keyframes, "a waving flag", r.seed).unwrap();
            assert!(
                rows_diff(got, &alone) < 1e-5,
                "{mode:?} seed {}: {}",
                r.seed,
                rows_diff(got, &alone)
            );
        }
        assert!(
            rows_diff(&batch[0][N..2 * N], &batch[2][N..2 * N]) > 1e-4,
            "seeds differ inside a batch"
        );
    }
}

#[test]
fn keyframe_slots_hold_the_keyframe_latents_after_sampling() {
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let gt = wave_clip();
    let keys = [0, 2, 3];
    // μ of every frame, encoded independently of the sampler.
    let all = codec.encode(&gt, &(0..T).collect::<Vec<_>>()).unwrap();
    let mu_all = floats(all.mu.clone());
    for (net, mode) in [
        (KeyframeConditioning::InputMask, KeyframeConditioning::InputMask),
        (KeyframeConditioning::None, KeyframeConditioning::ReplaceNoised),
    ] {
        let sampler = RfSampler::new(models(codec.clone(), net, &device), options(mode), 1.0).unwrap();
        let visible = hide_non_keyframes(&gt, &keys);
        let s = sampler.sample_latents(&visible, &keys, "flag", 5).unwrap();
        assert_eq!(s.latents.dims(), [1, T, P, C]);
        assert_eq!(s.mask, vec![1.0, 0.0, 1.0, 1.0]);
        let (z, key) = (floats(s.latents.clone()), floats(s.keyframe_latents.clone()));
        for &f in &keys {
            assert_eq!(slot(&z, f), slot(&key, f), "{mode:?}: slot {f} is the keyframe latent");
            assert!(
                max_diff(slot(&key, f), slot(&mu_all, f)) < 1e-5,
                "{mode:?}: keyframe latent = μ of frame {f}"
            );
        }
        assert!(
            max_diff(slot(&z, 1), slot(&mu_all, 1)) > 1e-3,
            "{mode:?}: slot 1 is generated"
        );
        // Decoded keyframe frames equal vae.decode(μ) of that keyframe alone.
        let decoded = sampler.sample(&visible, &keys, "flag", 5).unwrap();
        for &f in &keys {
            let mu_f = all.mu.clone().narrow(1, f, 1);
            let alone = codec.decode(&all, mu_f).unwrap();
            let err = rows_diff(&decoded[f * N..(f + 1) * N], &alone);
            assert!(
                err < 1e-4,
                "{mode:?}: decoded keyframe {f} differs from decode(μ) by {err}"
            );
        }
    }
}

#[test]
fn zero_velocity_leaves_the_seeded_noise_de_standardized() {
    // An untouched MMDiT has a zero-initialised output layer: v = 0, so X₁ = X₀ = ε (τ = 0 is noise) and the
    // non-keyframe latents are ε · std + mean of the motion statistics (docs/method.md §3.4, §4.6).
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let cfg = MmditConfig {
        frames: T,
        channels: C,
        ..MmditConfig::tiny()
    };
    let m = Arc::new(LearnedModels::new(codec, cfg.init(&device), cfg, stats(), Box::new(ByteText)).unwrap());
    let s = RfSampler::new(m, options(KeyframeConditioning::InputMask), 1.0)
        .unwrap()
        .sample_latents(&wave_clip(), &[0, 3], "flag", 11)
        .unwrap();
    let eps = sampler_noise(11, [1, P, T, C], &device).swap_dims(1, 2); // [1, T, P, C]
    let expect = floats(eps.mul_scalar(stats().motion_std).add_scalar(stats().motion_mean));
    let z = floats(s.latents);
    for f in [1, 2] {
        assert!(max_diff(slot(&z, f), slot(&expect, f)) < 1e-5, "frame {f}");
    }
    assert!(
        max_diff(slot(&z, 3), slot(&expect, 3)) > 1e-2,
        "keyframe 3 is not noise"
    );
    let other = floats(sampler_noise(12, [1, P, T, C], &device));
    assert!(max_diff(&other, &floats(sampler_noise(11, [1, P, T, C], &device))) > 0.1);
}

/// docs/method.md §8 X14: at noise scale 0 the seed no longer matters; a negative or non-finite scale is refused.
#[test]
fn rf_sampler_noise_scale_zero_is_seed_free_and_bad_scales_are_refused() {
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::InputMask,
        &device,
    );
    let zero = SampleOptions {
        noise_scale: 0.0,
        ..options(KeyframeConditioning::InputMask)
    };
    let sampler = RfSampler::new(m.clone(), zero, 1.0).unwrap();
    let (gt, keys) = (wave_clip(), [0, 3]);
    let visible = hide_non_keyframes(&gt, &keys);
    let a = sampler.sample(&visible, &keys, "a waving flag", 42).unwrap();
    let b = sampler.sample(&visible, &keys, "a waving flag", 43).unwrap();
    assert!(rows_diff(&a, &b) < 1e-6, "scale 0 still depends on the seed");
    for bad in [-0.5, f64::NAN, f64::INFINITY] {
        let opts = SampleOptions {
            noise_scale: bad,
            ..zero
        };
        let err = RfSampler::new(m.clone(), opts, 1.0).err().expect("refused").to_string();
        assert!(err.contains("noise_scale") && err.contains("≥ 0"), "{err}");
    }
}

#[test]
fn sample_latents_match_a_hand_wired_sample_mmdit() {
    // Reference wiring from the model API: standardized z₀ and μ, mask [1, T], ε of the seed, (R6), de-standardize.
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let cfg = MmditConfig {
        frames: T,
        channels: C,
        ..MmditConfig::tiny()
    };
    let rf = cfg.init(&device).map(&mut WakeZeros);
    let m = Arc::new(LearnedModels::new(codec.clone(), rf.clone(), cfg, stats(), Box::new(ByteText)).unwrap());
    let opts = options(KeyframeConditioning::InputMask);
    let gt = wave_clip();
    let got = RfSampler::new(m, opts, 1.0)
        .unwrap()
        .sample_latents(&gt, &[3, 0], "flag", 3)
        .unwrap();

    let st = stats();
    let enc = codec.encode(&gt, &(0..T).collect::<Vec<_>>()).unwrap();
    let cond = Conditioning {
        z0: st.standardize_shape(enc.z0.clone()),
        z_key: st.standardize_motion(enc.mu.clone()).swap_dims(1, 2),
        mask: Tensor::from_data(TensorData::new(vec![1.0f32, 0.0, 0.0, 1.0], [1, T]), &device),
        scene: None,
    };
    let text = ByteText.encode(&["flag".to_string()], &device).unwrap().states;
    let keep = Tensor::ones([1], &device);
    let x1 = sample_mmdit(
        &rf,
        &cond,
        text,
        keep,
        sampler_noise(3, [1, P, T, C], &device),
        1.0,
        &opts,
    );
    let expect = floats(st.destandardize_motion(x1).swap_dims(1, 2));
    let err = max_diff(&floats(got.latents), &expect);
    assert!(err < 1e-4, "latents differ from the hand-wired sampler by {err}");
}

#[test]
fn impute_until_samples_and_differs_from_input_mask() {
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::InputMask,
        &device,
    );
    let gt = wave_clip();
    let keys = [0, 2, 3];
    let impute = MethodKind::ImputeUntil {
        tau_star: 0.5,
        keyframes: any4d_eval::methods::KeyframeNoise::Clean,
    };
    let base = options(KeyframeConditioning::InputMask);
    let s = RfSampler::for_method(impute, m.clone(), base, 1.0).unwrap();
    assert_eq!(
        (s.options().conditioning, s.options().tau_star),
        (KeyframeConditioning::ImputeUntil, 0.5)
    );
    let a = s.sample_latents(&gt, &keys, "flag", 9).unwrap();
    let b = RfSampler::for_method(MethodKind::KeyframeRf, m.clone(), base, 1.0)
        .unwrap()
        .sample_latents(&gt, &keys, "flag", 9)
        .unwrap();
    let (za, zb) = (floats(a.latents), floats(b.latents));
    assert!(
        max_diff(slot(&za, 2), slot(&zb, 2)) > 1e-4,
        "after τ* the keyframe slots are denoised, not clamped"
    );
    assert_eq!(s.sample(&gt, &keys, "flag", 9).unwrap().len(), T * N);
    // CFG w ≠ 1 runs both branches and changes the result.
    let guided = RfSampler::new(m, base, 3.0)
        .unwrap()
        .sample_latents(&gt, &keys, "flag", 9)
        .unwrap();
    assert!(
        max_diff(slot(&floats(guided.latents), 1), slot(&zb, 1)) > 1e-5,
        "guidance reaches the sampler"
    );
}

/// `KeyPosterior::Sample`: μ + σξ with ξ fixed by the seed, the clip id and the frame — the same frame gets the same
/// draw whichever other frames are encoded with it; the mean codec hands on μ itself.
#[test]
fn sampled_keyframe_latents_are_per_frame_and_reproducible() {
    use any4d_eval::learned::KeyPosterior;
    let device = Device::flex();
    let vae = FrameVaeConfig::tiny().init(&device).map(&mut WakeZeros);
    let codec = |posterior| {
        MeshCodec::new(AnyMeshVae::Framewise(vae.clone()), P, PadTo::BatchMax, device.clone())
            .unwrap()
            .with_posterior(posterior)
    };
    let gt = wave_clip();
    let mean = codec(KeyPosterior::Mean).encode(&gt, &[0, 1, 3]).unwrap();
    let sample = codec(KeyPosterior::Sample { seed: 1 });
    let a = sample.encode(&gt, &[0, 1, 3]).unwrap();
    let again = sample.encode(&gt, &[0, 1, 3]).unwrap();
    assert_eq!(floats(a.mu.clone()), floats(again.mu.clone()), "reproducible");
    assert!(
        max_diff(&floats(a.mu.clone()), &floats(mean.mu.clone())) > 1e-4,
        "a sample is not μ"
    );
    let alone = sample.encode(&gt, &[3]).unwrap();
    assert_eq!(
        floats(a.mu.clone().narrow(1, 2, 1)),
        floats(alone.mu),
        "frame 3 draws the same noise alone or with others"
    );
    let other = codec(KeyPosterior::Sample { seed: 2 }).encode(&gt, &[0, 1, 3]).unwrap();
    assert!(
        max_diff(&floats(a.mu), &floats(other.mu)) > 1e-4,
        "another seed, another draw"
    );
}

/// `ReplaceNoise::Fresh` (docs/method.md §8 X9) is reproducible from the request seeds, and differs from fixed noise
/// and between seeds.
#[test]
fn fresh_replacement_noise_is_seed_reproducible() {
    use any4d_model::rectified_flow::ReplaceNoise;
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::ReplaceNoised,
        &device,
    );
    let fresh = SampleOptions {
        replace_noise: ReplaceNoise::Fresh,
        ..options(KeyframeConditioning::ReplaceNoised)
    };
    let sampler = RfSampler::new(m.clone(), fresh, 1.0).unwrap();
    let fixed = RfSampler::new(m, options(KeyframeConditioning::ReplaceNoised), 1.0).unwrap();
    let gt = wave_clip();
    let keys = [0, 3];
    let visible = hide_non_keyframes(&gt, &keys);
    let a = sampler.sample(&visible, &keys, "flag", 5).unwrap();
    let b = sampler.sample(&visible, &keys, "flag", 5).unwrap();
    assert_eq!(a, b, "same seed, same fresh noise");
    let other = sampler.sample(&visible, &keys, "flag", 6).unwrap();
    assert!(rows_diff(&a, &other) > 1e-6, "another seed, other noise");
    let f = fixed.sample(&visible, &keys, "flag", 5).unwrap();
    assert!(rows_diff(&a, &f) > 1e-6, "fresh noise is not the fixed ε");
}

/// An empty caption is the same network input as the unconditional branch of classifier-free guidance: sampling
/// with "" at w = 1 equals sampling any caption at w = 0 (v = v_u), and whitespace counts as empty.
#[test]
fn an_empty_caption_samples_the_unconditional_branch() {
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::InputMask,
        &device,
    );
    let cond = RfSampler::new(m.clone(), options(KeyframeConditioning::InputMask), 1.0).unwrap();
    let uncond = RfSampler::new(m, options(KeyframeConditioning::InputMask), 0.0).unwrap();
    let gt = wave_clip();
    let keys = [0, 3];
    let visible = hide_non_keyframes(&gt, &keys);
    let empty = cond.sample(&visible, &keys, "", 7).unwrap();
    let no_text = uncond.sample(&visible, &keys, "a waving flag", 7).unwrap();
    assert!(rows_diff(&empty, &no_text) < 1e-5, "empty caption ≠ the no-text branch");
    let blank = cond.sample(&visible, &keys, "   ", 7).unwrap();
    assert!(rows_diff(&empty, &blank) < 1e-5, "whitespace is not an empty caption");
    let flag = cond.sample(&visible, &keys, "a waving flag", 7).unwrap();
    assert!(rows_diff(&empty, &flag) > 1e-6, "the caption reaches the network");
}

#[test]
fn rf_method_returns_decoded_keyframes_and_scoring_assembles_ground_truth_ones() {
    let device = Device::flex();
    let m = models(
        frame_codec(&device, PadTo::BatchMax),
        KeyframeConditioning::InputMask,
        &device,
    );
    let sampler =
        RfSampler::for_method(MethodKind::KeyframeRf, m, options(KeyframeConditioning::InputMask), 1.0).unwrap();
    let method = RfMethod::new(MethodKind::KeyframeRf, sampler).unwrap();
    let gt = wave_clip();
    let keys = [0, 3];
    let out = method
        .complete(&hide_non_keyframes(&gt, &keys), &keys, "flag", 1)
        .unwrap();
    // The untrained VAE does not reproduce frame 3, so the raw keyframe differs from the ground truth …
    assert!(
        rows_diff(&out[3 * N..4 * N], gt.frame(3)) > 1e-4,
        "keyframe 3 is decoded"
    );
    assert!(rows_diff(&out[N..2 * N], gt.frame(1)) > 1e-3, "frame 1 is generated");
    // … and (E7) sees it, while the assembled prediction carries the ground-truth keyframes.
    let s = complete_and_score(&method, &gt, &keys, "flag", 1).unwrap();
    assert!(s.metrics.keyframe_rmse > 1e-5, "(E7) = {}", s.metrics.keyframe_rmse);
    for &f in &keys {
        assert_eq!(&s.prediction[f * N..(f + 1) * N], gt.frame(f), "keyframe {f}");
    }
}

#[test]
fn latent_lerp_interpolates_keyframe_latents_and_decodes_them() {
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let lerp = LatentLerpSampler::new(codec.clone()).unwrap();
    let gt = wave_clip();
    let keys = [0, 3];
    let visible = hide_non_keyframes(&gt, &keys);
    let all = codec.encode(&gt, &(0..T).collect::<Vec<_>>()).unwrap();
    let mu = floats(all.mu.clone());
    let (_, z) = lerp.latents(&visible, &keys).unwrap();
    let z = floats(z);
    for f in 0..T {
        let w = f as f32 / 3.0;
        let expect: Vec<f32> = slot(&mu, 0)
            .iter()
            .zip(slot(&mu, 3))
            .map(|(a, b)| a + w * (b - a))
            .collect();
        assert!(max_diff(slot(&z, f), &expect) < 1e-5, "(L1) on z at frame {f}");
    }
    let out = lerp.sample(&visible, &keys, "", 0).unwrap();
    assert_eq!(out.len(), T * N);
    for f in keys {
        let alone = codec.decode(&all, all.mu.clone().narrow(1, f, 1)).unwrap();
        let err = rows_diff(&out[f * N..(f + 1) * N], &alone);
        assert!(err < 1e-4, "lerp at keyframe {f} is decode(μ_{f}); error {err}");
    }
    let err = lerp.sample(&visible, &[0, 2], "", 0).unwrap_err();
    assert!(err.to_string().contains("first and last"), "{err}");
}

#[test]
fn the_vae_oracle_decodes_every_ground_truth_frame_whatever_the_keyframes() {
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let oracle = VaeOracleSampler::new(codec.clone());
    let gt = wave_clip();
    let expect = codec.reconstruct(&gt).unwrap();
    let out = oracle.sample(&gt, &[0, T - 1], "", 0).unwrap();
    assert_eq!(out.len(), T * N);
    assert!(rows_diff(&out, &expect) < 1e-6, "(E4) of the whole window");
    let other = oracle.sample(&gt, &[0, 1, T - 1], "a caption", 7).unwrap();
    assert!(
        rows_diff(&other, &out) < 1e-6,
        "keyframes, caption and seed do not enter"
    );
    let mut moved = gt.clone();
    for v in &mut moved.vertices[N..2 * N] {
        v[0] += 0.5;
    }
    let changed = oracle.sample(&moved, &[0, T - 1], "", 0).unwrap();
    assert!(
        rows_diff(&changed[N..2 * N], &out[N..2 * N]) > 1e-3,
        "a non-keyframe's ground truth reaches its decoded frame"
    );
    // The scorer shows it the whole window (every other row sees only the keyframes), then assembles as usual.
    let method = RfMethod::new(MethodKind::VaeOracle, oracle).unwrap();
    let keys = [0, T - 1];
    let s = complete_and_score(&method, &gt, &keys, "", 0).unwrap();
    for f in 1..T - 1 {
        let err = rows_diff(&s.prediction[f * N..(f + 1) * N], &expect[f * N..(f + 1) * N]);
        assert!(
            err < 1e-6,
            "frame {f} is the decoded ground truth, not the decoded reference; error {err}"
        );
    }
    for &f in &keys {
        assert_eq!(&s.prediction[f * N..(f + 1) * N], gt.frame(f), "keyframe {f}");
    }
    let inner = [0, 1, T - 1];
    let asks: [(&[usize], u64); 2] = [(&keys, 0), (&inner, 1)];
    for (s, (k, _)) in complete_and_score_batch(&method, &gt, &asks, "", None)
        .unwrap()
        .iter()
        .zip(asks)
    {
        let f = T - 2;
        let err = rows_diff(&s.prediction[f * N..(f + 1) * N], &expect[f * N..(f + 1) * N]);
        assert!(
            err < 1e-6 || k.contains(&f),
            "batched (table 1's path): frame {f} decoded from the truth; error {err}"
        );
    }
}

/// The VAE batch of a whole clip, built by hand from the data crate (the cross-check of the codec).
fn vae_batch(clip: &Clip, device: &Device) -> VaeBatch {
    let flat = |rows: &[[f32; 3]]| rows.iter().flatten().copied().collect::<Vec<f32>>();
    let fps: Vec<i64> = farthest_point_sampling(clip.frame(0), P)
        .into_iter()
        .map(i64::from)
        .collect();
    let edges = edges_from_faces(&clip.faces, N).unwrap();
    VaeBatch {
        reference: Tensor::from_data(TensorData::new(flat(clip.frame(0)), [1, N, 3]), device),
        frames: Tensor::from_data(TensorData::new(flat(&clip.vertices), [1, T, N, 3]), device),
        vmask: Tensor::from_data(TensorData::new(vec![true; N], [1, N]), device),
        fps: Tensor::from_data(TensorData::new(fps, [1, P]), device),
        edges: EdgeList::new(&[edges], N, device).unwrap(),
        noise_seed: None,
    }
}

#[test]
fn vae_reconstructors_match_the_model_reconstruct() {
    let device = Device::flex();
    let gt = wave_clip();
    let batch = vae_batch(&gt, &device);
    let frame = FrameVaeConfig::tiny().init(&device).map(&mut WakeZeros);
    let expect_frame = floats(frame.reconstruct(&batch, Posterior::Mean).0);
    let seq = DyMeshVaeConfig::tiny().with_frames(T).init(&device).map(&mut WakeZeros);
    let expect_seq = floats(seq.reconstruct(&batch, Posterior::Mean).0);
    assert!(
        max_diff(&expect_frame, &gt.vertices.concat()) > 1e-3,
        "the woken VAE does not copy its input"
    );

    let rows = |codec: MeshCodec| {
        VaeReconstructor::new("row", Arc::new(codec))
            .reconstruct(&gt)
            .unwrap()
            .concat()
    };
    let f = rows(MeshCodec::new(AnyMeshVae::Framewise(frame.clone()), P, PadTo::BatchMax, device.clone()).unwrap());
    assert!(max_diff(&f, &expect_frame) < 1e-5, "frame-wise (E4)");
    let padded = rows(MeshCodec::new(AnyMeshVae::Framewise(frame), P, PadTo::Fixed(N + 7), device.clone()).unwrap());
    assert!(
        max_diff(&padded, &expect_frame) < 1e-4,
        "masked padded keys do not change the latents"
    );
    let s = rows(MeshCodec::new(AnyMeshVae::Sequencewise(seq), P, PadTo::BatchMax, device).unwrap());
    assert!(max_diff(&s, &expect_seq) < 1e-5, "sequence-wise (E4)");
}

#[test]
fn mismatched_parts_and_bad_windows_are_errors() {
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let m = models(codec.clone(), KeyframeConditioning::InputMask, &device);
    let e = RfSampler::new(m.clone(), options(KeyframeConditioning::ReplaceNoised), 1.0)
        .err()
        .expect("layout mismatch");
    assert!(e.to_string().contains("mask channels"), "{e}");
    assert!(
        RfSampler::for_method(
            MethodKind::Lerp,
            m.clone(),
            options(KeyframeConditioning::InputMask),
            1.0
        )
        .is_err()
    );
    let sampler = RfSampler::new(m, options(KeyframeConditioning::InputMask), 1.0).unwrap();
    let gt = wave_clip();
    let e = sampler.sample(&gt, &[0, 7], "", 0).unwrap_err();
    assert!(e.to_string().contains("frame 7"), "{e}");
    let mut short = gt.clone();
    short.frames = 3;
    short.vertices.truncate(3 * N);
    let e = sampler.sample(&short, &[0, 2], "", 0).unwrap_err();
    assert!(e.to_string().contains("T = 4"), "{e}");

    let cfg = MmditConfig {
        frames: T,
        channels: C,
        text_dim: 16,
        ..MmditConfig::tiny()
    };
    let e = LearnedModels::new(codec, cfg.init(&device), cfg, stats(), Box::new(ByteText))
        .err()
        .expect("text width");
    assert!(e.to_string().contains("text_dim 16"), "{e}");
    let seq = DyMeshVaeConfig::tiny().with_frames(T).init(&device);
    let seq_codec =
        Arc::new(MeshCodec::new(AnyMeshVae::Sequencewise(seq), P, PadTo::BatchMax, device.clone()).unwrap());
    assert!(LatentLerpSampler::new(seq_codec.clone()).is_err());
    // An RF on the sequence-wise VAE has one trajectory slot and no keyframes (the AnimateAnyMesh reference).
    let per_frame = MmditConfig {
        frames: T,
        channels: C,
        ..MmditConfig::tiny()
    };
    let e = LearnedModels::new(
        seq_codec.clone(),
        per_frame.init(&device),
        per_frame,
        stats(),
        Box::new(ByteText),
    )
    .err()
    .expect("slots");
    assert!(e.to_string().contains("one trajectory slot"), "{e}");
    let e = seq_codec.encode(&gt, &[0, 3]).unwrap_err();
    assert!(e.to_string().contains("whole windows"), "{e}");
}

/// Paper-size cost of one window on the CPU (P = 512, N = 1024, T = 16, 12 × 512 MMDiT, d = 128 VAE), with a
/// 2-point grid (one midpoint step = 2 network evaluations) so that it finishes; multiply the sampling part by 63
/// for the paper's 64-point grid.
/// `cargo test -p any4d-eval --test learned paper_size -- --ignored --nocapture`
#[test]
#[ignore = "paper-size timing, tens of seconds on a CPU"]
fn paper_size_window_timing() {
    use std::time::Instant;
    let device = Device::flex();
    let (t, side) = (16, 32);
    let n = side * side;
    let mut vertices = Vec::with_capacity(t * n);
    for f in 0..t {
        for i in 0..side {
            for j in 0..side {
                let (x, y) = (i as f32 / 15.5 - 1.0, j as f32 / 15.5 - 1.0);
                vertices.push([x, y, 0.3 * (2.0 * x + 0.3 * f as f32).sin()]);
            }
        }
    }
    let s = side as u32;
    let faces = (0..s - 1)
        .flat_map(|i| (0..s - 1).map(move |j| i * s + j))
        .flat_map(|v| [[v, v + 1, v + s], [v + 1, v + s + 1, v + s]])
        .collect();
    let clip = Clip::new("big_offset0_0-16", vertices, t, n, faces, "flag", "test").unwrap();
    let vae = FrameVaeConfig::paper().init(&device);
    let codec = Arc::new(MeshCodec::new(AnyMeshVae::Framewise(vae), 512, PadTo::BatchMax, device.clone()).unwrap());
    let cfg = MmditConfig::paper(KeyframeConditioning::InputMask, 8);
    let rf = cfg.init(&device);
    let m = Arc::new(LearnedModels::new(codec.clone(), rf, cfg, stats(), Box::new(ByteText)).unwrap());
    let opts = SampleOptions {
        n_grid: 2,
        ..SampleOptions::paper(KeyframeConditioning::InputMask)
    };
    let sampler = RfSampler::new(m, opts, 1.0).unwrap();
    let keys = [0, 5, 15];
    let start = Instant::now();
    let enc = codec.encode(&clip, &keys).unwrap();
    let encode_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let s = sampler.sample_latents(&clip, &keys, "flag", 42).unwrap();
    let sample_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let out = codec.decode(&s.encoding, s.latents).unwrap();
    let decode_s = start.elapsed().as_secs_f64();
    assert_eq!(out.len(), t * n);
    drop(enc);
    println!(
        "encode 3 keyframes {encode_s:.2} s; sample_latents (encode + 2 evals) {sample_s:.2} s; decode 16 frames {decode_s:.2} s"
    );
}

/// docs/method.md §4.12 at sampling: a network reading the keyframe offsets (S4) only — so nothing but the offsets
/// can carry the scene — is told the request's scene: a box under the flag changes the sample against no scene. The
/// anchors of (S2) are the window encoding's FPS tokens (frame 0's farthest points, as the store's). A network without
/// scene parts samples the same with or without a scene.
#[test]
fn a_scene_aware_rf_reads_the_requests_scene_and_a_plain_one_ignores_it() {
    use any4d_data::scene::Scene;
    use any4d_model::mmdit::SceneConditioning;
    let device = Device::flex();
    let codec = frame_codec(&device, PadTo::BatchMax);
    let gt = wave_clip();
    let anchors = codec.encode(&gt, &[0]).unwrap().anchors;
    let fps: Vec<u32> = farthest_point_sampling(gt.frame(0), P);
    assert_eq!(anchors, fps);
    let floor = Scene::cuboid([-2.0, -2.0, -1.0], [2.0, 2.0, -0.4]);
    let method = |scene_parts: bool| {
        let mut cfg = MmditConfig {
            frames: T,
            channels: C,
            ..MmditConfig::tiny()
        };
        if scene_parts {
            cfg.scene = SceneConditioning {
                global: false,
                local: true,
                grid: [8, 4, 8],
                cell: 0.5,
                patch: 4,
            };
        }
        let rf = cfg.init(&device).map(&mut WakeZeros);
        let m = Arc::new(LearnedModels::new(codec.clone(), rf, cfg, stats(), Box::new(ByteText)).unwrap());
        let sampler = RfSampler::new(m, options(KeyframeConditioning::InputMask), 1.0).unwrap();
        RfMethod::new(MethodKind::KeyframeRf, sampler).unwrap()
    };
    let sample = |method: &dyn Method, scene: Option<&Scene>| {
        let keys: &[usize] = &[0, 1, 3];
        complete_and_score_batch(method, &gt, &[(keys, 5)], "flag", scene).unwrap()[0]
            .prediction
            .clone()
    };
    let (aware, plain) = (method(true), method(false));
    let with_scene = sample(&aware, Some(&floor));
    assert!(
        rows_diff(&with_scene, &sample(&aware, Some(&floor))) == 0.0,
        "not reproducible"
    );
    assert!(
        rows_diff(&with_scene, &sample(&aware, None)) > 1e-4,
        "the scene is not read"
    );
    assert!(
        rows_diff(&sample(&plain, None), &sample(&plain, Some(&floor))) == 0.0,
        "a plain network reads the scene"
    );
}
