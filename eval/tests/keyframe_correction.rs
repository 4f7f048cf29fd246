//! Keyframe correction (docs/method.md §5.6, (L2)): a decoder's error that moves linearly in time between keyframes is
//! removed exactly, a completion that already matches its keyframes is left alone, only keyframe frames are read,
//! and the `_corrected` labels wrap latent methods only.

use any4d_data::Clip;
use any4d_eval::baselines::correct_by_keyframes;
use any4d_eval::methods::{
    CorrectedBase, KeyframeCorrected, Method, MethodKind, complete_and_score, hide_non_keyframes,
};
use any4d_eval::metrics::Motion;

/// Four vertices on a curved, non-linear path over `frames` frames.
fn curved_clip(frames: usize) -> Clip {
    let vertices = (0..frames)
        .flat_map(|f| {
            let t = f as f32 / 5.0;
            (0..4).map(move |v| {
                let v = v as f32;
                [v + t.sin() * 0.3, (t * (1.0 + v)).cos() * 0.2, 0.1 * v * t * t]
            })
        })
        .collect();
    Clip::new(
        "curve_0-16",
        vertices,
        frames,
        4,
        vec![[0, 1, 2], [0, 2, 3]],
        "bends",
        "test",
    )
    .unwrap()
}

/// A stand-in decoder: the ground truth plus, per vertex, a bias `b + f · d` that drifts linearly with the frame f.
/// It reads the truth it holds, not its input: the point is the shape of its error.
struct Biased {
    kind: MethodKind,
    truth: Clip,
}

fn bias(f: usize, v: usize) -> [f32; 3] {
    let (f, v) = (f as f32, v as f32);
    [0.05 + 0.01 * v + 0.004 * f, -0.03 + 0.002 * f, 0.02 * v - 0.003 * f * v]
}

impl Method for Biased {
    fn kind(&self) -> MethodKind {
        self.kind
    }

    fn complete(
        &self,
        clip: &Clip,
        _keys: &[usize],
        _caption: &str,
        _seed: u64,
    ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
        let n = clip.n_vertices;
        Ok(self
            .truth
            .vertices
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let b = bias(i / n, i % n);
                [x[0] + b[0], x[1] + b[1], x[2] + b[2]]
            })
            .collect())
    }
}

#[test]
fn a_decoding_error_linear_in_time_between_keyframes_is_removed_exactly() {
    let gt = curved_clip(16);
    let keys = [0, 5, 15];
    let kind = MethodKind::Corrected {
        base: CorrectedBase::KeyframeRf,
    };
    let raw = complete_and_score(
        &Biased {
            kind: MethodKind::KeyframeRf,
            truth: gt.clone(),
        },
        &gt,
        &keys,
        "",
        1,
    )
    .unwrap();
    assert!(raw.metrics.rmse > 0.01, "the stand-in is wrong: {}", raw.metrics.rmse);
    let inner = Box::new(Biased {
        kind: MethodKind::KeyframeRf,
        truth: gt.clone(),
    });
    let corrected = KeyframeCorrected::new(kind, inner).unwrap();
    assert_eq!(corrected.kind().label(), "keyframe_rf_corrected");
    let scored = complete_and_score(&corrected, &gt, &keys, "", 1).unwrap();
    assert!(scored.metrics.rmse < 1e-5, "corrected RMSE {}", scored.metrics.rmse);
    assert!(scored.metrics.keyframe_rmse < 1e-6, "keyframes become the given ones");
}

#[test]
fn a_completion_that_matches_its_keyframes_is_left_alone_and_hidden_frames_are_not_read() {
    let gt = curved_clip(16);
    let keys = [0, 9, 15];
    // A completion equal to the truth at the keyframes and wrong elsewhere: zero residuals, nothing moves.
    let mut prediction: Vec<[f32; 3]> = gt.vertices.iter().map(|x| [x[0] + 0.1, x[1], x[2] - 0.2]).collect();
    for &k in &keys {
        prediction[k * 4..(k + 1) * 4].copy_from_slice(gt.frame(k));
    }
    let before = prediction.clone();
    correct_by_keyframes(&mut prediction, Motion::from_clip(&gt).unwrap(), &keys).unwrap();
    assert_eq!(prediction, before);
    // The window a method is shown (non-keyframes hidden) gives the same correction as the whole truth.
    let mut shown = before.clone();
    for p in &mut shown {
        p[1] += 0.05;
    }
    let mut from_truth = shown.clone();
    correct_by_keyframes(
        &mut shown,
        Motion::from_clip(&hide_non_keyframes(&gt, &keys)).unwrap(),
        &keys,
    )
    .unwrap();
    correct_by_keyframes(&mut from_truth, Motion::from_clip(&gt).unwrap(), &keys).unwrap();
    assert_eq!(shown, from_truth);
    let off = shown
        .iter()
        .flatten()
        .zip(before.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(
        off < 1e-6,
        "a uniform shift is a residual the keyframes see everywhere: {off}"
    );
}

#[test]
fn bad_shapes_and_keyframes_are_errors() {
    let gt = curved_clip(16);
    let given = Motion::from_clip(&gt).unwrap();
    let mut short = vec![[0.0f32; 3]; 15 * 4];
    assert!(correct_by_keyframes(&mut short, given, &[0, 15]).is_err());
    let mut full = gt.vertices.clone();
    assert!(
        correct_by_keyframes(&mut full, given, &[0, 7]).is_err(),
        "the last frame must be a keyframe"
    );
    assert!(
        correct_by_keyframes(&mut full, given, &[0, 15, 16]).is_err(),
        "a keyframe past the window"
    );
    let mut nan = gt.vertices.clone();
    nan[20][1] = f32::NAN;
    assert!(
        correct_by_keyframes(&mut nan, given, &[0, 15]).is_err(),
        "a non-finite prediction"
    );
}

#[test]
fn corrected_labels_wrap_latent_methods_only() {
    for base in [
        CorrectedBase::KeyframeRf,
        CorrectedBase::KeyframeRfMean { samples: 8 },
        CorrectedBase::ReplacementRf,
        CorrectedBase::LerpLatent,
        CorrectedBase::Bdlstm,
    ] {
        assert_eq!(CorrectedBase::of(base.kind()), Some(base));
        let kind = MethodKind::Corrected { base };
        assert_eq!(kind.label(), format!("{}_corrected", base.kind().label()));
        assert_eq!(MethodKind::parse(&kind.label()).unwrap(), kind);
        assert!(kind.needs_model());
    }
    for bad in [
        "lerp_corrected",
        "static_nearest_corrected",
        "vae_oracle_corrected",
        "keyframe_rf_corrected_corrected",
        "_corrected",
        "aam_corrected",
        "keyframe_rf_mean1_corrected",
    ] {
        assert!(MethodKind::parse(bad).is_err(), "{bad}");
    }
    let gt = curved_clip(16);
    let lerp_latent = MethodKind::Corrected {
        base: CorrectedBase::LerpLatent,
    };
    let wrong_inner = Box::new(Biased {
        kind: MethodKind::KeyframeRf,
        truth: gt.clone(),
    });
    assert!(KeyframeCorrected::new(lerp_latent, wrong_inner).is_err());
    let inner = Box::new(Biased {
        kind: MethodKind::KeyframeRf,
        truth: gt,
    });
    assert!(KeyframeCorrected::new(MethodKind::KeyframeRf, inner).is_err());
}
