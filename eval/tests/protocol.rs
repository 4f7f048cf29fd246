//! Protocol tests (docs/method.md §6.1): the manifest is deterministic, nested, validated on load; methods see only
//! keyframes.

use any4d_data::Clip;
use any4d_data::keyframes::Placement;
use any4d_eval::baselines::VertexBaseline;
use any4d_eval::methods::{
    KeyframeNoise, Method, MethodKind, Request, SampleMean, VertexMethod, complete_and_score, hide_non_keyframes,
    mean_sample_seed, noisy_keyframes,
};
use any4d_eval::protocol::{Candidate, ClipRef, Manifest, ManifestOptions, long_horizon_pairs, noise_seed};

fn candidates(n: usize) -> Vec<Candidate> {
    (0..n)
        .map(|i| Candidate {
            clip: ClipRef {
                index: i,
                id: format!("obj{i}_offset0_0-16"),
            },
            next: None,
        })
        .collect()
}

fn opts(n: usize) -> ManifestOptions {
    ManifestOptions {
        n_clips: n,
        ..ManifestOptions::table1("synthetic")
    }
}

#[test]
fn manifest_is_deterministic_nested_and_keeps_first_and_last() {
    let m = Manifest::build(&candidates(300), &opts(100), "store").unwrap();
    assert_eq!(m, Manifest::build(&candidates(300), &opts(100), "store").unwrap());
    let other = Manifest::build(&candidates(300), &ManifestOptions { seed: 43, ..opts(100) }, "store").unwrap();
    assert_ne!(m.clips, other.clips, "the seed must change the draw");
    assert_eq!(m.clips.len(), 100);
    let mut ids: Vec<usize> = m.clips.iter().map(|c| c.clip.index).collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), 100, "clips are drawn without replacement");
    let mut interior_seen = [0usize; 16];
    for item in &m.clips {
        assert_eq!(item.keyframes.len(), 4);
        for (k, set) in item.keyframes.iter().enumerate() {
            assert_eq!(set.len(), k + 2, "K_x = {k}: {set:?}");
            assert_eq!((set[0], set[set.len() - 1]), (0, 15));
            if k > 0 {
                assert!(
                    item.keyframes[k - 1].iter().all(|f| set.contains(f)),
                    "not nested: {:?}",
                    item.keyframes
                );
            }
        }
        for &f in &item.keyframes[3][1..4] {
            interior_seen[f] += 1;
        }
    }
    assert!(
        interior_seen[1..15].iter().all(|&n| n > 0),
        "every interior frame is drawn sometimes: {interior_seen:?}"
    );
    m.validate().unwrap();
}

#[test]
fn manifest_round_trips_and_rejects_broken_files_by_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("manifest.json");
    let m = Manifest::build(&candidates(20), &opts(10), "store").unwrap();
    m.save(&path).unwrap();
    assert_eq!(Manifest::load(&path).unwrap(), m);

    let mut broken = m.clone();
    broken.clips[3].keyframes[2] = vec![0, 5, 9, 15]; // wrong size for K_x = 2
    std::fs::write(&path, serde_json::to_string(&broken).unwrap()).unwrap();
    let e = Manifest::load(&path).unwrap_err();
    assert_eq!(e.field(), "clips[3].keyframes[2]", "{e}");
    assert!(e.what().ends_with("manifest.json"), "{e}");

    let mut unnested = m.clone();
    let k1 = unnested.clips[0].keyframes[1].clone();
    let outside = (1..15).find(|f| !k1.contains(f)).unwrap();
    unnested.clips[0].keyframes[2] = {
        let mut s = vec![
            0,
            15,
            outside,
            (1..15).find(|f| !k1.contains(f) && *f != outside).unwrap(),
        ];
        s.sort_unstable();
        s
    };
    let e = unnested.validate().unwrap_err();
    assert!(e.reason().contains("does not contain"), "{e}");

    std::fs::write(&path, "{\"version\": 1,").unwrap();
    let e = Manifest::load(&path).unwrap_err();
    assert!(e.field().starts_with("line"), "{e}");
}

#[test]
fn too_few_candidates_is_an_error() {
    let e = Manifest::build(&candidates(5), &opts(100), "data/dir").unwrap_err();
    assert_eq!((e.what(), e.field()), ("data/dir", "clips"));
    assert!(e.reason().contains("5 candidate"), "{e}");
}

#[test]
fn other_placements_keep_the_ends() {
    let every = ManifestOptions {
        placement: Placement::EveryR { r: 4 },
        ..opts(3)
    };
    let m = Manifest::build(&candidates(3), &every, "s").unwrap();
    assert_eq!(m.clips[0].keyframes, vec![vec![0, 4, 8, 12, 15]]);
    let none = ManifestOptions {
        placement: Placement::Bernoulli { p: 0.0 },
        ..opts(3)
    };
    assert_eq!(
        Manifest::build(&candidates(3), &none, "s").unwrap().clips[1].keyframes,
        vec![vec![0, 15]]
    );
    let all = ManifestOptions {
        placement: Placement::Bernoulli { p: 1.0 },
        ..opts(3)
    };
    assert_eq!(
        Manifest::build(&candidates(3), &all, "s").unwrap().clips[2].keyframes[0].len(),
        16
    );
    let long = ManifestOptions {
        n_clips: 2,
        ..ManifestOptions::table2("s")
    };
    assert_eq!(
        Manifest::build(&candidates(2), &long, "s").unwrap().clips[0].keyframes,
        vec![vec![0, 15, 30]]
    );
    let bad = ManifestOptions {
        placement: Placement::Random { k_extra_max: 15 },
        ..opts(3)
    };
    assert_eq!(
        Manifest::build(&candidates(3), &bad, "s").unwrap_err().field(),
        "placement"
    );
}

#[test]
fn noise_seeds_differ_per_clip_and_base() {
    let seeds: Vec<u64> = (0..100).map(|i| noise_seed(42, i)).collect();
    let mut unique = seeds.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), 100);
    assert_eq!(noise_seed(42, 7), seeds[7]);
    assert_ne!(noise_seed(43, 7), seeds[7]);
}

#[test]
fn long_horizon_pairs_share_the_boundary_frame() {
    let refs: Vec<ClipRef> = [
        "a_offset0_0-16",
        "a_offset0_15-31",
        "a_offset0_30-46",
        "b_offset0_0-16",
        "b_offset0_16-32",
        "plain",
    ]
    .iter()
    .enumerate()
    .map(|(i, id)| ClipRef {
        index: i,
        id: id.to_string(),
    })
    .collect();
    let pairs = long_horizon_pairs(&refs);
    let ids: Vec<(usize, usize)> = pairs
        .iter()
        .map(|c| (c.clip.index, c.next.as_ref().unwrap().index))
        .collect();
    assert_eq!(
        ids,
        vec![(0, 1), (1, 2)],
        "b starts 16 later (no shared frame), `plain` is not AAM form"
    );
}

/// A linear-motion clip: vertex v of frame f at base_v + f · vel_v.
pub fn linear_clip(frames: usize) -> Clip {
    let base = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let vel = [
        [0.01, 0.0, 0.02],
        [0.0, -0.03, 0.0],
        [0.02, 0.01, 0.0],
        [0.0, 0.0, -0.01],
    ];
    let vertices = (0..frames)
        .flat_map(|f| (0..4).map(move |v| [0, 1, 2].map(|k| base[v][k] + f as f32 * vel[v][k])))
        .collect();
    Clip::new(
        "lin_offset0_0-16",
        vertices,
        frames,
        4,
        vec![[0, 1, 2], [0, 2, 3]],
        "moves",
        "test",
    )
    .unwrap()
}

/// A method that returns whatever it was given: it exposes what the protocol lets it see.
struct Peek;
impl Method for Peek {
    fn kind(&self) -> MethodKind {
        MethodKind::KeyframeRf
    }
    fn complete(
        &self,
        clip: &Clip,
        _k: &[usize],
        _c: &str,
        _s: u64,
    ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
        Ok(clip.vertices.clone())
    }
}

#[test]
fn methods_see_only_keyframes_and_lerp_is_exact_on_linear_motion() {
    let gt = linear_clip(16);
    let keys = [0, 6, 15];
    let hidden = hide_non_keyframes(&gt, &keys);
    assert_eq!(hidden.frame(3), gt.frame(0), "non-keyframes show the reference mesh");
    assert_eq!(hidden.frame(6), gt.frame(6));
    let peek = complete_and_score(&Peek, &gt, &keys, "", 1).unwrap();
    assert!(
        peek.metrics.rmse > 1e-3,
        "a method that copies its input must not recover hidden frames"
    );
    let lerp = complete_and_score(&VertexMethod(VertexBaseline::Linear), &gt, &keys, "", 1).unwrap();
    assert!(lerp.metrics.rmse < 1e-5, "lerp on linear motion: {}", lerp.metrics.rmse);
    for &k in &keys {
        assert_eq!(
            &lerp.prediction[k * 4..(k + 1) * 4],
            gt.frame(k),
            "keyframe {k} returned exactly"
        );
    }
    let nearest = complete_and_score(&VertexMethod(VertexBaseline::NearestKeyframe), &gt, &keys, "", 1).unwrap();
    assert!(nearest.metrics.rmse > lerp.metrics.rmse);
    assert!(
        nearest.metrics.energy_ratio < 1.0,
        "held keyframes move less than the truth"
    );
}

#[test]
fn method_labels_round_trip() {
    for kind in [
        MethodKind::KeyframeRf,
        MethodKind::ReplacementRf,
        MethodKind::Lerp,
        MethodKind::LerpLatent,
        MethodKind::VaeOracle,
        MethodKind::StaticNearest,
        MethodKind::Bdlstm,
        MethodKind::BdlstmAcap,
        MethodKind::Aam,
        MethodKind::KeyframeRfMean { samples: 8 },
        MethodKind::ImputeUntil {
            tau_star: 0.98,
            keyframes: KeyframeNoise::Clean,
        },
        MethodKind::ImputeUntil {
            tau_star: 0.96,
            keyframes: KeyframeNoise::Noisy { level: 1.0 },
        },
    ] {
        assert_eq!(MethodKind::parse(&kind.label()).unwrap(), kind, "{kind}");
    }
    assert!(MethodKind::parse("bd_lstm").is_err());
    assert_eq!(
        MethodKind::parse("impute_until_1.5").unwrap_err().field(),
        "impute_until_1.5"
    );
}

#[test]
fn keyframe_noise_spares_the_ends_and_has_the_set_scale() {
    let gt = linear_clip(16);
    let noisy = noisy_keyframes(&gt, &[0, 5, 15], 1.0, 3);
    assert_eq!(noisy.frame(0), gt.frame(0));
    assert_eq!(noisy.frame(15), gt.frame(15));
    assert_eq!(noisy.frame(4), gt.frame(4), "only keyframes are perturbed");
    let d: Vec<f32> = noisy
        .frame(5)
        .iter()
        .zip(gt.frame(5))
        .flat_map(|(a, b)| (0..3).map(move |k| a[k] - b[k]))
        .collect();
    assert!(
        d.iter().any(|x| x.abs() > 1e-4) && d.iter().all(|x| x.abs() < 0.02 * 6.0),
        "{d:?}"
    );
    assert_eq!(
        noisy,
        noisy_keyframes(&gt, &[0, 5, 15], 1.0, 3),
        "deterministic by seed"
    );
}

/// A stand-in sampler whose raw output misses the keyframes (as a decoded RF sample does).
struct Drifting;
use any4d_eval::methods::WindowSampler;
impl WindowSampler for Drifting {
    fn sample(
        &self,
        clip: &Clip,
        _k: &[usize],
        _c: &str,
        seed: u64,
    ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
        Ok(clip
            .vertices
            .iter()
            .map(|p| [p[0] + 0.05, p[1] - 0.02, p[2] + seed as f32 * 1e-3])
            .collect())
    }
}

#[test]
fn rf_methods_are_scored_on_their_raw_keyframes_then_assembled() {
    use any4d_eval::methods::RfMethod;
    let gt = linear_clip(16);
    let keys = [0, 4, 11, 15];
    for kind in [MethodKind::ReplacementRf, MethodKind::KeyframeRf] {
        let m = RfMethod::new(kind, Drifting).unwrap();
        let raw = m.complete(&hide_non_keyframes(&gt, &keys), &keys, "", 7).unwrap();
        assert_ne!(
            &raw[4 * 4..5 * 4],
            gt.frame(4),
            "{kind}: the method returns its own keyframes"
        );
        let s = complete_and_score(&m, &gt, &keys, "", 7).unwrap();
        for &k in &keys {
            assert_eq!(
                &s.prediction[k * 4..(k + 1) * 4],
                gt.frame(k),
                "{kind}: assembled keyframe {k}"
            );
        }
        // (E7) measures the drift of the raw keyframes, (0.05, −0.02, 0.007) per vertex, in the frame of the ground
        // truth's frame 0 (half-extent 0.5, so twice as large).
        let drift = ((0.05f64.powi(2) + 0.02f64.powi(2) + 0.007f64.powi(2)) / 3.0).sqrt() / 0.5;
        assert!(
            (s.metrics.keyframe_rmse - drift).abs() < 1e-4,
            "{kind}: (E7) = {} vs {drift}",
            s.metrics.keyframe_rmse
        );
        assert!(s.metrics.rmse > 0.01, "non-keyframes keep the sampler's output");
    }
    let noisy = MethodKind::ImputeUntil {
        tau_star: 0.98,
        keyframes: KeyframeNoise::Noisy { level: 1.0 },
    };
    let visible = hide_non_keyframes(&gt, &keys);
    let raw = RfMethod::new(noisy, Drifting)
        .unwrap()
        .complete(&visible, &keys, "", 7)
        .unwrap();
    let clean = Drifting.sample(&visible, &keys, "", 7).unwrap();
    assert_ne!(
        &raw[4 * 4..5 * 4],
        &clean[4 * 4..5 * 4],
        "noisy keyframes are what the sampler is given"
    );
    assert_eq!(&raw[..4], &clean[..4], "the first frame stays clean");
    assert!(RfMethod::new(MethodKind::Lerp, Drifting).is_err());
}

/// A stochastic stand-in: every coordinate of every frame is the seed's low byte, and it counts its requests.
struct SeedEcho(std::sync::atomic::AtomicUsize);

impl Method for SeedEcho {
    fn kind(&self) -> MethodKind {
        MethodKind::KeyframeRf
    }

    fn complete(
        &self,
        clip: &Clip,
        _keyframes: &[usize],
        _caption: &str,
        seed: u64,
    ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
        self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        Ok(vec![[(seed & 0xff) as f32; 3]; clip.frames * clip.n_vertices])
    }
}

#[test]
fn a_mean_of_samples_averages_the_seeded_completions_with_sample_0_first() {
    let kind = MethodKind::parse("keyframe_rf_mean4").unwrap();
    assert_eq!(kind, MethodKind::KeyframeRfMean { samples: 4 });
    assert_eq!(MethodKind::parse(&kind.label()).unwrap(), kind);
    for bad in [
        "keyframe_rf_mean1",
        "keyframe_rf_mean65",
        "keyframe_rf_meanx",
        "keyframe_rf_mean",
    ] {
        assert!(MethodKind::parse(bad).is_err(), "{bad}");
    }
    assert!(SampleMean::new(MethodKind::Lerp, Box::new(SeedEcho(Default::default()))).is_err());
    let method = SampleMean::new(kind, Box::new(SeedEcho(Default::default()))).unwrap();
    let clip = linear_clip(16);
    let seed = 0x1234_5600 + 7;
    assert_eq!(mean_sample_seed(seed, 0), seed);
    let want = (0..4).map(|k| (mean_sample_seed(seed, k) & 0xff) as f32).sum::<f32>() / 4.0;
    let out = method.complete(&clip, &[0, 15], "", seed).unwrap();
    assert_eq!(out.len(), 16 * 4);
    assert!(
        out.iter().flatten().all(|&v| (v - want).abs() < 1e-4),
        "{:?} vs {want}",
        out[0]
    );
    // Two requests in one batch: eight inner completions, each request averaged on its own.
    let other = method.complete(&clip, &[0, 15], "", 99).unwrap();
    let both = method
        .complete_batch(
            &[
                Request {
                    clip: &clip,
                    keyframes: &[0, 15],
                    seed,
                    scene: None,
                },
                Request {
                    clip: &clip,
                    keyframes: &[0, 15],
                    seed: 99,
                    scene: None,
                },
            ],
            "",
        )
        .unwrap();
    assert_eq!(both, vec![out, other]);
}
