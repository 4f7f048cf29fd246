//! Tests of the evaluation metrics (docs/method.md §6.1–§6.2) and the non-learned baselines (docs/method.md §5.2):
//! hand-worked cases, properties (docs/method.md §9 item 14 bounds), malformed input, and a reference test against
//! `scripts/metrics_reference.py` (numpy + scipy), whose output is committed in `tests/fixtures/`.

use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};
use any4d_eval::baselines::{VertexBaseline, lerp_latents};
use any4d_eval::metrics::{
    ClipMetrics, Coordinates, EvalError, Motion, Scoring, acceleration, average, centroid_dtw, chamfer, chamfer_sets,
    dtw_path, evaluate_clip, evaluate_clip_with, jerk, mae_elem, mean_vertex_error, motion_energy, non_keyframes,
    replace_keyframes, rmse, vae_reconstruction,
};
use serde::Deserialize;

/// SplitMix64 (the workspace's one, `any4d_data::rng::splitmix64`) as a tiny deterministic generator.
struct Gen(u64);

impl Gen {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        let z = splitmix64(self.0);
        (z >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }

    fn points(&mut self, rows: usize, scale: f32) -> Vec<[f32; 3]> {
        (0..rows).map(|_| [0; 3].map(|_| self.next_f32() * scale)).collect()
    }
}

fn motion(v: &[[f32; 3]], frames: usize) -> Motion<'_> {
    Motion::new(v, frames, v.len() / frames).unwrap()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

#[test]
fn rmse_mae_and_vertex_error_by_hand() {
    // One frame, two vertices, ground truth at the origin; errors (1,0,0) and (0,2,0):
    // RMSE = sqrt((1 + 4) / 6), mae_elem = (1 + 2) / 6 = 0.5, mean vertex error = (1 + 2) / 2 = 1.5.
    let p = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
    let g = [[0.0; 3]; 2];
    let (p, g) = (motion(&p, 1), motion(&g, 1));
    assert!(close(rmse(p, g, &[0]).unwrap(), (5.0f64 / 6.0).sqrt(), 1e-12));
    assert!(close(mae_elem(p, g, &[0]).unwrap(), 0.5, 1e-12));
    assert!(close(mean_vertex_error(p, g, &[0]).unwrap(), 1.5, 1e-12));
}

#[test]
fn rmse_of_translation_is_d_over_sqrt3() {
    let mut rng = Gen(1);
    let g = rng.points(4 * 10, 1.0);
    let d = 0.25f32;
    let p: Vec<[f32; 3]> = g.iter().map(|v| [v[0] + d, v[1], v[2]]).collect();
    let r = rmse(motion(&p, 4), motion(&g, 4), &[0, 1, 2, 3]).unwrap();
    // Each vertex contributes d² once over three axes: RMSE = sqrt(d²/3) = d/√3.
    assert!(close(r, f64::from(d) / 3f64.sqrt(), 1e-6), "{r}");
}

#[test]
fn chamfer_by_hand() {
    // p = {0, e_x}, g = {0}: g→p 0, p→g mean(0, 1) = 0.5.
    let p = [[0.0; 3], [1.0, 0.0, 0.0]];
    assert!(close(chamfer_sets(&p, &[[0.0; 3]]).unwrap(), 0.5, 1e-12));
    // p = {0}, g = {(3,4,0), (0,0,1)}: g→p mean(5, 1) = 3, p→g min(5, 1) = 1; total 4.
    let g = [[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]];
    assert!(close(chamfer_sets(&[[0.0; 3]], &g).unwrap(), 4.0, 1e-12));
    // Per-frame mean over two frames: frame 0 as in the first case (0.5), frame 1 identical (0): 0.25.
    let pv = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]];
    let gv = [[0.0; 3], [0.0; 3], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]];
    assert!(close(
        chamfer(motion(&pv, 2), motion(&gv, 2), &[0, 1]).unwrap(),
        0.25,
        1e-12
    ));
    assert!(close(
        chamfer(motion(&pv, 2), motion(&gv, 2), &[1]).unwrap(),
        0.0,
        1e-12
    ));
}

#[test]
fn chamfer_is_symmetric_and_zero_on_equal_sets() {
    let mut rng = Gen(2);
    let a = rng.points(300, 1.0);
    let b = rng.points(200, 1.0);
    let ab = chamfer_sets(&a, &b).unwrap();
    assert!(ab > 0.0);
    assert!(close(ab, chamfer_sets(&b, &a).unwrap(), 1e-12));
    let mut shuffled = a.clone();
    shuffled.reverse();
    assert_eq!(chamfer_sets(&a, &shuffled).unwrap(), 0.0);
}

/// Brute-force (E2) for one frame pair in f64: every pair of points compared.
fn chamfer_brute(p: &[[f32; 3]], g: &[[f32; 3]]) -> f64 {
    let d = |a: &[f32; 3], b: &[f32; 3]| (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum::<f64>().sqrt();
    let one_way = |from: &[[f32; 3]], to: &[[f32; 3]]| {
        from.iter()
            .map(|a| to.iter().map(|b| d(a, b)).fold(f64::INFINITY, f64::min))
            .sum::<f64>()
            / from.len() as f64
    };
    one_way(g, p) + one_way(p, g)
}

#[test]
fn chamfer_of_frames_is_the_brute_force_nearest_neighbour_distance() {
    // Frames of one mesh: the search is bounded by the same-index vertex, which must never change the nearest
    // distance, whether the prediction is near the truth (a tight bound), far from it (a loose one), or holds
    // repeated points. (The k-d tree's empty-result fallback is not reached here: the loosened bound always holds that
    // vertex.)
    let mut rng = Gen(5);
    let (frames, n) = (3, 400);
    let gt = rng.points(frames * n, 1.0);
    for noise in [0.0, 1e-3, 0.05, 2.0] {
        let mut pred: Vec<[f32; 3]> = gt
            .iter()
            .map(|g| [0, 1, 2].map(|k| g[k] + rng.next_f32() * noise))
            .collect();
        pred[7] = pred[8]; // a repeated point: two candidates at the same distance
        let expected: f64 = (0..frames)
            .map(|t| chamfer_brute(&pred[t * n..(t + 1) * n], &gt[t * n..(t + 1) * n]))
            .sum::<f64>()
            / frames as f64;
        let got = chamfer(motion(&pred, frames), motion(&gt, frames), &[0, 1, 2]).unwrap();
        assert!(
            close(got, expected, 1e-6),
            "noise {noise}: {got} vs brute force {expected}"
        );
        // The same sets with each predicted frame's vertices in reverse order: no index correspondence left.
        let reversed: Vec<[f32; 3]> = pred.chunks(n).flat_map(|f| f.iter().rev().copied()).collect();
        let got = chamfer(motion(&reversed, frames), motion(&gt, frames), &[0, 1, 2]).unwrap();
        assert!(
            close(got, expected, 1e-6),
            "noise {noise}, reversed order: {got} vs {expected}"
        );
    }
}

#[test]
fn dtw_by_hand_and_tie_order() {
    let line = |xs: &[f64]| xs.iter().map(|&x| [x, 0.0, 0.0]).collect::<Vec<_>>();
    // a = [0, 1], b = [1, 0]: costs [[1, 0], [0, 1]]; acc(1,1) = 1 + min(1, 1, 1) = 2. All three predecessors tie,
    // the diagonal wins: π* = (0,0), (1,1), DTW = 2 / 2 = 1 (another choice would give 2 / 3).
    let d = dtw_path(&line(&[0.0, 1.0]), &line(&[1.0, 0.0])).unwrap();
    assert_eq!(d.path, vec![(0, 0), (1, 1)]);
    assert_eq!(d.normalised(), 1.0);
    // a = [0, 1, 2, 0], b = [1, 0, 0, 2], costs |a_i − b_j|; accumulated rows:
    //   [1, 1, 1, 3], [1, 2, 2, 2], [2, 3, 4, 2], [3, 2, 2, 4].
    // From (3,3): diagonal 4, up (2,3) = 2, left (3,2) = 2 → tie, (i − 1, j) wins; then (2,3) → (1,2) (diagonal 2
    // ties up 2), (1,2) → (0,1) (diagonal 1 ties up 1), → (0,0). |π*| = 5, DTW = 4 / 5 (left would give 4 / 6).
    let d = dtw_path(&line(&[0.0, 1.0, 2.0, 0.0]), &line(&[1.0, 0.0, 0.0, 2.0])).unwrap();
    assert_eq!(d.path, vec![(0, 0), (0, 1), (1, 2), (2, 3), (3, 3)]);
    assert_eq!(d.cost, 4.0);
    assert!(close(d.normalised(), 0.8, 1e-12));
}

#[test]
fn dtw_of_equal_sequences_is_zero_and_uses_centroids() {
    let mut rng = Gen(3);
    let g = rng.points(6 * 5, 1.0);
    assert_eq!(
        centroid_dtw(motion(&g, 6), motion(&g, 6), &[0, 1, 2, 3, 4, 5]).unwrap(),
        0.0
    );
    // Permuting vertices inside each frame keeps every centroid: DTW stays 0 although RMSE does not.
    let p: Vec<[f32; 3]> = g.chunks(5).flat_map(|f| f.iter().rev().copied()).collect();
    assert!(centroid_dtw(motion(&p, 6), motion(&g, 6), &[1, 2, 4]).unwrap() < 1e-7);
    assert!(rmse(motion(&p, 6), motion(&g, 6), &[1, 2, 4]).unwrap() > 0.1);
}

#[test]
fn jerk_acceleration_energy_by_hand() {
    // One vertex moving along x. x_f = f³: third difference 6 → jerk 6 (r = 1), 6·2³ = 48 (r = 2).
    let cubic: Vec<[f32; 3]> = (0..6).map(|f| [(f * f * f) as f32, 0.0, 0.0]).collect();
    assert!(close(jerk(motion(&cubic, 6), 1.0).unwrap(), 6.0, 1e-12));
    assert!(close(jerk(motion(&cubic, 6), 2.0).unwrap(), 48.0, 1e-12));
    // x_f = f²: second difference 2 → acceleration 2 (r = 1), 2·10² = 200 (r = 10); jerk 0.
    let square: Vec<[f32; 3]> = (0..5).map(|f| [0.0, (f * f) as f32, 0.0]).collect();
    assert!(close(acceleration(motion(&square, 5), 1.0).unwrap(), 2.0, 1e-12));
    assert!(close(acceleration(motion(&square, 5), 10.0).unwrap(), 200.0, 1e-12));
    assert_eq!(jerk(motion(&square, 5), 1.0).unwrap(), 0.0);
    // x_f = (f, f, 0)·… step (1, 1, 0): energy = √2 per frame step.
    let line: Vec<[f32; 3]> = (0..4).map(|f| [f as f32, f as f32, 0.0]).collect();
    assert!(close(motion_energy(motion(&line, 4)).unwrap(), 2f64.sqrt(), 1e-12));
}

/// A smooth random clip: ground truth and a noisy prediction, `frames × n` vertices.
fn random_clip(seed: u64, frames: usize, n: usize, noise: f32) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut rng = Gen(seed);
    let base = rng.points(n, 1.0);
    let vel = rng.points(1, 0.1)[0];
    let gt: Vec<[f32; 3]> = (0..frames)
        .flat_map(|f| {
            base.iter()
                .map(move |b| [0, 1, 2].map(|k| b[k] + vel[k] * f as f32))
                .collect::<Vec<_>>()
        })
        .collect();
    let pred = gt
        .iter()
        .map(|g| [0, 1, 2].map(|k| g[k] + noise * rng.next_f32()))
        .collect();
    (pred, gt)
}

#[test]
fn keyframes_are_excluded_and_replaced() {
    let (pred, gt) = random_clip(4, 8, 20, 0.1);
    let keys = [0, 3, 7];
    let a = evaluate_clip(motion(&pred, 8), motion(&gt, 8), &keys).unwrap();
    let mut moved = pred.clone();
    for v in &mut moved[3 * 20..4 * 20] {
        v[1] += 5.0; // frame 3 is a keyframe
    }
    let b = evaluate_clip(motion(&moved, 8), motion(&gt, 8), &keys).unwrap();
    assert_eq!(
        (a.rmse, a.mae_elem, a.chamfer, a.dtw),
        (b.rmse, b.mae_elem, b.chamfer, b.dtw)
    );
    assert_eq!(
        (a.jerk, a.accel, a.energy),
        (b.jerk, b.accel, b.energy),
        "seams use the replaced keyframe"
    );
    assert!(
        b.keyframe_rmse > a.keyframe_rmse + 0.1,
        "(E7) sees the prediction before replacement"
    );
    // Moving a non-keyframe does change RMSE.
    moved[4 * 20][0] += 1.0;
    assert!(evaluate_clip(motion(&moved, 8), motion(&gt, 8), &keys).unwrap().rmse > a.rmse);
    assert_eq!(non_keyframes(8, &[7, 0, 3, 3]).unwrap(), vec![1, 2, 4, 5, 6]);
    let assembled = replace_keyframes(motion(&moved, 8), motion(&gt, 8), &keys).unwrap();
    assert_eq!(&assembled[3 * 20..4 * 20], &gt[3 * 20..4 * 20]);
    assert_eq!(assembled[4 * 20], moved[4 * 20]);
}

fn assert_bounds(m: &ClipMetrics) {
    let slack = 1e-9;
    assert!(
        m.dtw <= m.mean_vertex_error + slack,
        "DTW {} > mean vertex error {}",
        m.dtw,
        m.mean_vertex_error
    );
    assert!(m.mean_vertex_error <= 3f64.sqrt() * m.rmse + slack, "{m:?}");
    assert!(m.rmse <= 3f64.sqrt() * m.mae_elem + slack, "RMSE ≤ √3·MAE per vertex");
    assert!(
        m.chamfer <= 2.0 * m.mean_vertex_error + slack,
        "Chamfer {} > 2·{}",
        m.chamfer,
        m.mean_vertex_error
    );
}

#[test]
fn spec_bounds_hold_on_random_inputs() {
    // docs/method.md §9 item 14: DTW ≤ mean per-vertex error ≤ √3·RMSE, Chamfer ≤ 2·mean per-vertex error.
    for seed in 0..12u64 {
        let noise = [0.01, 0.3, 2.0][seed as usize % 3];
        let (pred, gt) = random_clip(100 + seed, 16, 30, noise);
        let keys = [0, 5 + seed as usize % 7, 15];
        let m = evaluate_clip(motion(&pred, 16), motion(&gt, 16), &keys).unwrap();
        assert_bounds(&m);
        assert!(m.rmse > 0.0 && m.chamfer > 0.0 && m.dtw > 0.0);
    }
}

#[test]
fn normalisation_uses_ground_truth_frame_zero() {
    let (pred, gt) = random_clip(5, 6, 16, 0.2);
    let keys = [0, 5];
    let base = evaluate_clip(motion(&pred, 6), motion(&gt, 6), &keys).unwrap();
    // The same similarity transform on both (scale 4, offset) leaves the normalised metrics unchanged…
    let warp = |v: &[[f32; 3]]| {
        v.iter()
            .map(|p| [p[0] * 4.0 + 10.0, p[1] * 4.0 - 3.0, p[2] * 4.0])
            .collect::<Vec<_>>()
    };
    let (wp, wg) = (warp(&pred), warp(&gt));
    let moved = evaluate_clip(motion(&wp, 6), motion(&wg, 6), &keys).unwrap();
    for (a, b) in [
        (base.rmse, moved.rmse),
        (base.chamfer, moved.chamfer),
        (base.dtw, moved.dtw),
        (base.jerk, moved.jerk),
    ] {
        assert!(close(a, b, 1e-5), "{a} vs {b}");
    }
    // …while the as-given coordinates scale with it.
    let as_given = Scoring {
        coordinates: Coordinates::AsGiven,
        rate: 1.0,
    };
    let raw = evaluate_clip_with(motion(&pred, 6), motion(&gt, 6), &keys, &as_given).unwrap();
    let raw_moved = evaluate_clip_with(motion(&wp, 6), motion(&wg, 6), &keys, &as_given).unwrap();
    assert!(close(raw_moved.rmse, 4.0 * raw.rmse, 1e-5));
    assert!(
        !close(raw.rmse, base.rmse, 1e-3),
        "normalisation changed the scale of this clip"
    );
}

#[test]
fn vae_reconstruction_scores_every_frame() {
    let (pred, gt) = random_clip(6, 5, 10, 0.1);
    let r = vae_reconstruction(motion(&pred, 5), motion(&gt, 5)).unwrap();
    let all = [0, 1, 2, 3, 4];
    assert_eq!(r.rmse, rmse(motion(&pred, 5), motion(&gt, 5), &all).unwrap());
    assert_eq!(r.chamfer, chamfer(motion(&pred, 5), motion(&gt, 5), &all).unwrap());
    assert_eq!(r.jerk, jerk(motion(&pred, 5), 1.0).unwrap());
    assert_eq!(r.jerk_gt, jerk(motion(&gt, 5), 1.0).unwrap());
    assert_ne!(
        r.jerk, r.jerk_gt,
        "decoded and input jerk are each their own sequence's"
    );
    let three: Vec<[f32; 3]> = gt[..3 * 10].to_vec();
    let short = vae_reconstruction(motion(&three, 3), motion(&three, 3)).unwrap();
    assert!(short.jerk.is_nan() && short.jerk_gt.is_nan(), "no jerk below 4 frames");
    assert_eq!(short.rmse, 0.0);
}

#[test]
fn average_is_field_wise_mean() {
    let (pred, gt) = random_clip(7, 6, 8, 0.1);
    let a = evaluate_clip(motion(&pred, 6), motion(&gt, 6), &[0, 5]).unwrap();
    let b = evaluate_clip(motion(&pred, 6), motion(&gt, 6), &[0, 2, 5]).unwrap();
    let m = average(&[a, b]).unwrap();
    assert!(close(m.rmse, (a.rmse + b.rmse) / 2.0, 1e-12));
    assert!(close(m.jerk_ratio, (a.jerk_ratio + b.jerk_ratio) / 2.0, 1e-12));
    assert_eq!(average(&[]), Err(EvalError::NoClips));
}

#[test]
fn malformed_input_names_what_differs() {
    let (pred, gt) = random_clip(8, 6, 5, 0.1);
    let short: Vec<[f32; 3]> = gt.chunks(5).flat_map(|f| f[..4].to_vec()).collect();
    let e = evaluate_clip(motion(&pred, 6), motion(&short, 6), &[0, 5]).unwrap_err();
    assert_eq!(
        e,
        EvalError::Mismatch {
            what: "vertex counts",
            pred: 5,
            gt: 4
        }
    );
    assert_eq!(
        e.to_string(),
        "vertex counts differ: prediction has 5, ground truth has 4"
    );
    let e = evaluate_clip(motion(&pred[..25], 5), motion(&gt, 6), &[0, 4]).unwrap_err();
    assert!(
        e.to_string()
            .contains("frame counts differ: prediction has 5, ground truth has 6"),
        "{e}"
    );
    let e = evaluate_clip(motion(&pred, 6), motion(&gt, 6), &[0, 6]).unwrap_err();
    assert_eq!(e.to_string(), "keyframe index 6 is out of range for 6 frames");
    let mut nan = gt.clone();
    nan[2 * 5 + 3][1] = f32::NAN;
    let e = evaluate_clip(motion(&pred, 6), motion(&nan, 6), &[0, 5]).unwrap_err();
    assert!(
        e.to_string().starts_with("ground truth: non-finite coordinate") && e.to_string().contains("frame 2, vertex 3"),
        "{e}"
    );
    let e = evaluate_clip(motion(&pred, 6), motion(&gt, 6), &[0, 1, 2, 3, 4, 5]).unwrap_err();
    assert!(matches!(e, EvalError::NoFrames(_)), "{e}");
    let e = evaluate_clip(motion(&pred[..15], 3), motion(&gt[..15], 3), &[0, 2]).unwrap_err();
    assert_eq!(
        e,
        EvalError::TooFewFrames {
            metric: "jerk",
            needed: 4,
            frames: 3
        }
    );
    let bad_rate = Scoring {
        coordinates: Coordinates::AsGiven,
        rate: 0.0,
    };
    assert!(evaluate_clip_with(motion(&pred, 6), motion(&gt, 6), &[0, 5], &bad_rate).is_err());
    assert_eq!(
        Motion::new(&gt[..7], 2, 5).unwrap_err().to_string(),
        "vertex array holds 7 rows, expected frames × vertices = 2 × 5"
    );
    assert!(matches!(
        rmse(motion(&pred, 6), motion(&gt, 6), &[]),
        Err(EvalError::NoFrames(_))
    ));
    assert_eq!(
        chamfer_sets(&[], &gt),
        Err(EvalError::EmptySet { name: "prediction set" })
    );
}

#[test]
fn linear_baseline_reproduces_linear_motion() {
    // x_f = x_0 + f·v is linear in f, so (L1) from any keyframe set containing 0 and T − 1 is exact.
    let mut rng = Gen(9);
    let (x0, v) = (rng.points(12, 1.0), rng.points(12, 0.2));
    let gt: Vec<[f32; 3]> = (0..16)
        .flat_map(|f| (0..12).map(move |i| (i, f)))
        .map(|(i, f)| [0, 1, 2].map(|k| x0[i][k] + f as f32 * v[i][k]))
        .collect();
    let out = VertexBaseline::Linear.complete(motion(&gt, 16), &[0, 6, 15]).unwrap();
    let err = rmse(motion(&out, 16), motion(&gt, 16), &(0..16).collect::<Vec<_>>()).unwrap();
    assert!(err < 1e-6, "{err}");
    // Only keyframes are read: scrambling the other ground-truth frames changes nothing.
    let mut scrambled = gt.clone();
    scrambled[3 * 12][0] = 99.0;
    assert_eq!(
        VertexBaseline::Linear
            .complete(motion(&scrambled, 16), &[0, 6, 15])
            .unwrap(),
        out
    );
    // Keyframes are copied bit-exactly.
    assert_eq!(&out[6 * 12..7 * 12], &gt[6 * 12..7 * 12]);
}

#[test]
fn nearest_keyframe_baseline_by_hand() {
    // One vertex, frames 0..4 at x = 0, 10, 20, 30, 40; keyframes {0, 3, 4}: frame 1 → 0 (distance 1 vs 2),
    // frame 2 → 3 (2 vs 1). With keyframes {0, 2, 4} frame 1 ties and takes the earlier keyframe 0.
    let gt: Vec<[f32; 3]> = (0..5).map(|f| [10.0 * f as f32, 0.0, 0.0]).collect();
    let xs = |out: Vec<[f32; 3]>| out.iter().map(|p| p[0]).collect::<Vec<_>>();
    let out = VertexBaseline::NearestKeyframe
        .complete(motion(&gt, 5), &[0, 3, 4])
        .unwrap();
    assert_eq!(xs(out), vec![0.0, 0.0, 30.0, 30.0, 40.0]);
    let out = VertexBaseline::NearestKeyframe
        .complete(motion(&gt, 5), &[0, 2, 4])
        .unwrap();
    assert_eq!(xs(out), vec![0.0, 0.0, 20.0, 20.0, 40.0]);
    let e = VertexBaseline::Linear.complete(motion(&gt, 5), &[0, 2]).unwrap_err();
    assert!(
        e.to_string().contains("must include the first and last frames 0 and 4"),
        "{e}"
    );
}

#[test]
fn latent_lerp_by_hand() {
    // Three frames of two values; keyframes {0, 2}: frame 1 = midpoint of (0, 0) and (2, 4) = (1, 2).
    let z = [0.0, 0.0, 9.0, 9.0, 2.0, 4.0];
    assert_eq!(
        lerp_latents(&z, 3, 2, &[0, 2]).unwrap(),
        vec![0.0, 0.0, 1.0, 2.0, 2.0, 4.0]
    );
    assert!(lerp_latents(&z[..5], 3, 2, &[0, 2]).is_err());
    assert!(lerp_latents(&[0.0, f32::NAN, 1.0, 1.0], 2, 2, &[0, 1]).is_err());
}

#[derive(Deserialize)]
struct Fixture {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    seed: u64,
    frames: usize,
    keyframes: Vec<usize>,
    rate: f64,
    pred: Vec<[f64; 3]>,
    gt: Vec<[f64; 3]>,
    expected: ClipMetrics,
    raw: Raw,
}

#[derive(Deserialize)]
struct Raw {
    rmse: f64,
    chamfer: f64,
    dtw: f64,
}

#[test]
fn matches_numpy_scipy_reference() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/metrics_reference.json");
    let text = std::fs::read_to_string(path).unwrap();
    let fixture: Fixture = serde_json::from_str(&text).unwrap();
    assert_eq!(fixture.cases.len(), 3);
    let to_f32 = |v: &[[f64; 3]]| v.iter().map(|p| p.map(|x| x as f32)).collect::<Vec<[f32; 3]>>();
    for case in &fixture.cases {
        let (pred, gt) = (to_f32(&case.pred), to_f32(&case.gt));
        let (p, g) = (motion(&pred, case.frames), motion(&gt, case.frames));
        let scoring = Scoring {
            coordinates: Coordinates::NormaliseByGtFrame0,
            rate: case.rate,
        };
        let got = evaluate_clip_with(p, g, &case.keyframes, &scoring).unwrap();
        let (got_v, want_v) = (
            serde_json::to_value(got).unwrap(),
            serde_json::to_value(case.expected).unwrap(),
        );
        let want = want_v.as_object().unwrap();
        assert_eq!(want.len(), 15);
        for (key, want) in want {
            let (a, b) = (got_v[key].as_f64().unwrap(), want.as_f64().unwrap());
            assert!(close(a, b, 1e-5), "seed {}: {key}: ours {a}, reference {b}", case.seed);
        }
        let all: Vec<usize> = (0..case.frames).collect();
        for (name, a, b) in [
            ("raw rmse", rmse(p, g, &all).unwrap(), case.raw.rmse),
            ("raw chamfer", chamfer(p, g, &all).unwrap(), case.raw.chamfer),
            ("raw dtw", centroid_dtw(p, g, &all).unwrap(), case.raw.dtw),
        ] {
            assert!(close(a, b, 1e-5), "seed {}: {name}: ours {a}, reference {b}", case.seed);
        }
        assert_bounds(&got);
    }
}
