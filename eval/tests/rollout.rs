//! Long-horizon rollout tests (docs/method.md §7, (H1)–(H4)): window layout, stitching without a duplicated frame 15,
//! normalisation round trip, overlap source, hidden frames, seam jerk.

use std::cell::RefCell;

use any4d_eval::baselines::VertexBaseline;
use any4d_eval::metrics::EvalError;
use any4d_eval::metrics::Motion;
use any4d_eval::rollout::{OverlapSource, RolloutSpec, WindowFrame, WindowInput, rollout, seam_jerk};

const N: usize = 4;

/// Vertex v of global frame f on a smooth, non-linear path (so a wrong frame index shows).
fn sequence(frames: usize) -> Vec<[f32; 3]> {
    let base = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    (0..frames)
        .flat_map(|f| {
            let t = f as f32 / 10.0;
            (0..N).map(move |v| {
                [
                    base[v][0] + t,
                    base[v][1] + (t * 1.3).sin() * (1.0 + v as f32),
                    base[v][2] * (1.0 + t * 0.5),
                ]
            })
        })
        .collect()
}

fn lerp(w: &WindowInput<'_>) -> Result<Vec<[f32; 3]>, EvalError> {
    let frames = w.vertices.len() / N;
    let m = Motion::new(&w.vertices, frames, N).unwrap();
    VertexBaseline::Linear
        .complete(m, &w.keyframes)
        .map_err(|e| any4d_eval::metrics::EvalError::invalid("lerp", "window", e.to_string()))
}

#[test]
fn window_layout_covers_any_length() {
    let s = RolloutSpec::paper();
    assert_eq!(s.starts(16).unwrap(), vec![0]);
    assert_eq!(s.starts(31).unwrap(), vec![0, 15]);
    assert_eq!(s.starts(46).unwrap(), vec![0, 15, 30]);
    assert_eq!(s.starts(40).unwrap(), vec![0, 15, 24]);
    assert_eq!(s.starts(15).unwrap_err().field(), "frames");
    assert!(RolloutSpec { stride: 16, ..s }.starts(31).is_err());
}

#[test]
fn thirty_one_frames_stitch_without_duplicating_frame_15() {
    let gt = sequence(31);
    // Each output frame carries the tag (window, local frame) in x; y, z are copied so (H1) stays well defined.
    let calls = RefCell::new(Vec::new());
    let tagger = |w: &WindowInput<'_>| -> Result<Vec<[f32; 3]>, EvalError> {
        calls
            .borrow_mut()
            .push((w.index, w.start, w.keyframes.clone(), w.caption.to_string()));
        Ok((0..16)
            .flat_map(|l| (0..N).map(move |_| [(w.index * 100 + l) as f32, 0.0, 0.0]))
            .collect())
    };
    let r = rollout(&gt, N, &[0, 15, 30], &["first", "second"], RolloutSpec::paper(), tagger).unwrap();
    assert_eq!(r.vertices.len(), 31 * N);
    assert_eq!(r.starts, vec![0, 15]);
    let calls = calls.into_inner();
    assert_eq!(calls[0], (0, 0, vec![0, 15], "first".to_string()));
    assert_eq!(calls[1], (1, 15, vec![0, 15], "second".to_string()));
    // Undo (H3) on window 1 to read the tags back.
    let f1 = r.frames[1];
    let tags: Vec<usize> = (0..31)
        .map(|f| {
            let p = r.vertices[f * N];
            let x = if f < 15 { p[0] } else { (p[0] - f1.center[0]) / f1.scale };
            x.round() as usize
        })
        .collect();
    let expected: Vec<usize> = (0..15).chain(100..116).collect();
    assert_eq!(
        tags, expected,
        "frames 0..15 from stage 1, 15..31 from stage 2, frame 15 exactly once"
    );
}

#[test]
fn lerp_rollout_reproduces_piecewise_linear_motion_through_h1_to_h3() {
    // Motion linear on [0, 15] and on [15, 30] with a kink at 15: lerp with keyframes 0/15/30 is exact.
    let gt: Vec<[f32; 3]> = (0..31usize)
        .flat_map(|f| {
            let a = f.min(15) as f32;
            let b = f.saturating_sub(15) as f32;
            (0..N).map(move |v| {
                [
                    v as f32 + 0.02 * a - 0.05 * b,
                    0.5 * (v % 2) as f32 + 0.03 * b,
                    -0.01 * a * v as f32,
                ]
            })
        })
        .collect();
    let r = rollout(&gt, N, &[0, 15, 30], &["p"], RolloutSpec::paper(), lerp).unwrap();
    let err = r
        .vertices
        .iter()
        .zip(&gt)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0f32, f32::max);
    assert!(err < 1e-5, "max error {err}");
    assert_ne!(
        r.frames[1],
        WindowFrame::IDENTITY,
        "stage 2 is re-normalised by its overlap frame"
    );
    let inside = r.frames[1].normalize(gt[15 * N + 1]);
    assert!(
        inside.iter().all(|c| c.abs() <= 1.0 + 1e-6),
        "(H2) maps the overlap frame into [-1, 1]: {inside:?}"
    );
}

#[test]
fn h1_falls_back_to_unit_scale() {
    assert_eq!(WindowFrame::from_overlap(&[[2.0, 3.0, 4.0]; 5]).scale, 1.0);
    assert_eq!(
        WindowFrame::from_overlap(&[[f32::NAN, 0.0, 0.0], [1.0, 1.0, 1.0]]).scale,
        1.0
    );
    let s = WindowFrame::from_overlap(&[[0.0, 0.0, 0.0], [2.0, 1.0, 0.0]]);
    assert_eq!((s.center, s.scale), ([1.0, 0.5, 0.0], 1.0));
    let s = WindowFrame::from_overlap(&[[0.0, 0.0, 0.0], [4.0, 1.0, 0.0]]);
    assert_eq!((s.center, s.scale), ([2.0, 0.5, 0.0], 2.0));
    let p = [3.0, -1.0, 0.5];
    assert_eq!(s.denormalize(s.normalize(p)), p);
}

#[test]
fn overlap_source_picks_the_reference_and_hidden_frames_stay_hidden() {
    let gt = sequence(31);
    let offset = |w: &WindowInput<'_>| -> Result<Vec<[f32; 3]>, EvalError> {
        // Every generated frame is the input shifted by 0.1 in x (keyframes too, as a raw sampler output would be).
        Ok(w.vertices.iter().map(|p| [p[0] + 0.1, p[1], p[2]]).collect())
    };
    let seen = RefCell::new(Vec::new());
    let record = |w: &WindowInput<'_>| {
        seen.borrow_mut().push(w.vertices.clone());
        offset(w)
    };
    let spec = RolloutSpec {
        overlap_source: OverlapSource::Generated,
        ..RolloutSpec::paper()
    };
    let r = rollout(&gt, N, &[0, 15, 30], &["p"], spec, record).unwrap();
    let seen = seen.into_inner();
    // Generated: window 1's reference is stage 1's output at frame 15 (gt + 0.1 before any replacement).
    let reference: Vec<[f32; 3]> = seen[1][..N].iter().map(|p| r.frames[1].denormalize(*p)).collect();
    for (a, b) in reference.iter().zip(&gt[15 * N..16 * N]) {
        assert!(
            (a[0] - (b[0] + 0.1)).abs() < 1e-5 && (a[1] - b[1]).abs() < 1e-5,
            "{a:?} vs {b:?}"
        );
    }
    // Hidden frames equal the reference (frame 0) in both windows.
    for v in &seen {
        assert_eq!(&v[3 * N..4 * N], &v[..N]);
    }
    // Ground truth: window 1's reference is the ground-truth frame 15.
    let seen_gt = RefCell::new(Vec::new());
    let record_gt = |w: &WindowInput<'_>| {
        seen_gt.borrow_mut().push(w.vertices.clone());
        offset(w)
    };
    let r = rollout(&gt, N, &[0, 15, 30], &["p"], RolloutSpec::paper(), record_gt).unwrap();
    let reference: Vec<[f32; 3]> = seen_gt.into_inner()[1][..N]
        .iter()
        .map(|p| r.frames[1].denormalize(*p))
        .collect();
    for (a, b) in reference.iter().zip(&gt[15 * N..16 * N]) {
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-5), "{a:?} vs {b:?}");
    }
}

#[test]
fn generator_errors_and_bad_inputs_are_reported() {
    let gt = sequence(31);
    let short = |_: &WindowInput<'_>| -> Result<Vec<[f32; 3]>, EvalError> { Ok(vec![[0.0; 3]; 3]) };
    let e = rollout(&gt, N, &[0, 15, 30], &["p"], RolloutSpec::paper(), short).unwrap_err();
    assert_eq!(e.field(), "window 0");
    let nan = |w: &WindowInput<'_>| -> Result<Vec<[f32; 3]>, EvalError> { Ok(vec![[f32::NAN; 3]; w.vertices.len()]) };
    assert!(
        rollout(&gt, N, &[0, 15, 30], &["p"], RolloutSpec::paper(), nan)
            .unwrap_err()
            .reason()
            .contains("non-finite")
    );
    assert_eq!(
        rollout(&gt, N, &[0, 15, 30], &["a", "b", "c"], RolloutSpec::paper(), lerp)
            .unwrap_err()
            .field(),
        "captions"
    );
    assert_eq!(
        rollout(&gt, N, &[0, 31], &["a"], RolloutSpec::paper(), lerp)
            .unwrap_err()
            .field(),
        "keyframes"
    );
}

#[test]
fn rolling_extension_runs_three_windows() {
    let gt = sequence(46);
    let r = rollout(&gt, N, &[0, 15, 30, 45], &["p"], RolloutSpec::paper(), lerp).unwrap();
    assert_eq!(r.starts, vec![0, 15, 30]);
    for k in [0, 15, 30, 45] {
        for (a, b) in r.vertices[k * N..(k + 1) * N].iter().zip(&gt[k * N..(k + 1) * N]) {
            assert!(
                (0..3).all(|c| (a[c] - b[c]).abs() < 1e-5),
                "keyframe {k}: {a:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn seam_jerk_is_zero_on_linear_motion_and_positive_at_a_kink() {
    let linear: Vec<[f32; 3]> = (0..31).map(|f| [f as f32 * 0.1, 0.0, 0.0]).collect();
    assert!(seam_jerk(&linear, 1, 15, 2, 1.0).unwrap() < 1e-6);
    let kink: Vec<[f32; 3]> = (0..31).map(|f| [f.min(15) as f32 * 0.1, 0.0, 0.0]).collect();
    // Band 13..=17: j_13 = x16 − 3x15 + 3x14 − x13 = −0.1 (|·| = 0.1), j_14 = x17 − 3x16 + 3x15 − x14 = 0.1.
    let j = seam_jerk(&kink, 1, 15, 2, 1.0).unwrap();
    assert!((j - 0.1).abs() < 1e-6, "{j}");
    assert_eq!(seam_jerk(&kink, 1, 15, 1, 1.0), None, "a ±1 band has only three frames");
}
