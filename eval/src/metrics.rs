//! Evaluation metrics (docs/method.md §6.2, (E1)–(E7)) as pure functions over vertex sequences, and the per-clip
//! protocol of docs/method.md §6.1: normalise by ground-truth frame 0 ((D1)–(D3)), replace keyframes with ground truth,
//! score 𝒰.
//!
//! Every metric reads f32 vertices and accumulates in f64. Sequences are frame-major `[T, N, 3]` slices
//! (vertex `v` of frame `f` at `f * N + v`), wrapped in [`Motion`] so frame and vertex counts travel with them.

use any4d_data::preprocess::Normalization;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::error::{EvalError, Result};
use crate::nearest::mean_nearest;
pub(crate) use crate::nearest::{norm, sub};

/// Owned vertex rows, frame-major `[T * N]` xyz.
pub type Rows = Vec<[f32; 3]>;

/// A borrowed vertex sequence `[T, N, 3]`, frame-major.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion<'a> {
    vertices: &'a [[f32; 3]],
    frames: usize,
    n_vertices: usize,
}

impl<'a> Motion<'a> {
    /// Wrap `vertices` (`frames * n_vertices` rows). Errors if the row count does not match.
    ///
    /// # Shapes
    /// `vertices`: `[T * N]` rows of xyz.
    pub fn new(vertices: &'a [[f32; 3]], frames: usize, n_vertices: usize) -> Result<Self> {
        if vertices.len() != frames * n_vertices {
            return Err(EvalError::Layout {
                rows: vertices.len(),
                frames,
                n_vertices,
            });
        }
        Ok(Self {
            vertices,
            frames,
            n_vertices,
        })
    }

    /// View a clip (already validated by the data crate).
    pub fn from_clip(clip: &'a any4d_data::Clip) -> Result<Self> {
        Self::new(&clip.vertices, clip.frames, clip.n_vertices)
    }

    /// Number of frames T.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// All rows, `[T * N]`.
    pub fn vertices(&self) -> &'a [[f32; 3]] {
        self.vertices
    }

    /// The `N` vertices of frame `f` (panics past the last frame; public metrics check indices first).
    pub fn frame(&self, f: usize) -> &'a [[f32; 3]] {
        &self.vertices[f * self.n_vertices..(f + 1) * self.n_vertices]
    }

    /// Errors on an empty sequence or a non-finite coordinate; `name` labels the error.
    pub fn check(&self, name: &'static str) -> Result<()> {
        if self.frames == 0 || self.n_vertices == 0 {
            return Err(EvalError::Empty {
                name,
                frames: self.frames,
                n_vertices: self.n_vertices,
            });
        }
        if let Some(i) = self.vertices.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(EvalError::NonFinite {
                name,
                frame: i / self.n_vertices,
                vertex: i % self.n_vertices,
                value: self.vertices[i],
            });
        }
        Ok(())
    }
}

/// Checks that prediction and ground truth are finite and have the same frame and vertex counts.
pub fn check_pair(pred: Motion, gt: Motion) -> Result<()> {
    if pred.n_vertices != gt.n_vertices {
        return Err(EvalError::Mismatch {
            what: "vertex counts",
            pred: pred.n_vertices,
            gt: gt.n_vertices,
        });
    }
    if pred.frames != gt.frames {
        return Err(EvalError::Mismatch {
            what: "frame counts",
            pred: pred.frames,
            gt: gt.frames,
        });
    }
    pred.check("prediction")?;
    gt.check("ground truth")
}

/// Checks a non-empty list of frame indices against `frames`.
fn check_frames(what: &'static str, indices: &[usize], frames: usize) -> Result<()> {
    if indices.is_empty() {
        return Err(EvalError::NoFrames(format!("the {what} list is empty")));
    }
    match indices.iter().find(|&&f| f >= frames) {
        Some(&index) => Err(EvalError::FrameOutOfRange { what, index, frames }),
        None => Ok(()),
    }
}

/// Sum over the listed frames of `f(p, g)` per vertex pair, and the number of pairs.
fn sum_pairs(pred: Motion, gt: Motion, frames: &[usize], f: impl Fn([f64; 3]) -> f64) -> (f64, usize) {
    let mut sum = 0.0;
    for &t in frames {
        for (p, g) in pred.frame(t).iter().zip(gt.frame(t)) {
            sum += f(sub(*p, *g));
        }
    }
    (sum, frames.len() * pred.n_vertices)
}

/// (E1) RMSE over the listed frames: `sqrt(1/(U·V·3) Σ (p − g)²)`.
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; `frames`: `[U]` indices into `0..T`.
pub fn rmse(pred: Motion, gt: Motion, frames: &[usize]) -> Result<f64> {
    check_pair(pred, gt)?;
    check_frames("scored frame", frames, pred.frames)?;
    let (sum, pairs) = sum_pairs(pred, gt, frames, |d| d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    Ok((sum / (3 * pairs) as f64).sqrt()) // (E1)
}

/// (E1) as printed in P-Eq. 15 with the implicit average: `mae_elem = 1/(U·V·3) Σ |p − g|` (docs/method.md §9 item 13).
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; `frames`: `[U]`.
pub fn mae_elem(pred: Motion, gt: Motion, frames: &[usize]) -> Result<f64> {
    check_pair(pred, gt)?;
    check_frames("scored frame", frames, pred.frames)?;
    let (sum, pairs) = sum_pairs(pred, gt, frames, |d| d[0].abs() + d[1].abs() + d[2].abs());
    Ok(sum / (3 * pairs) as f64)
}

/// Mean per-vertex Euclidean error `1/(U·V) Σ ‖p − g‖₂`: the quantity in the bounds of docs/method.md §9 item 14.
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; `frames`: `[U]`.
pub fn mean_vertex_error(pred: Motion, gt: Motion, frames: &[usize]) -> Result<f64> {
    check_pair(pred, gt)?;
    check_frames("scored frame", frames, pred.frames)?;
    let (sum, pairs) = sum_pairs(pred, gt, frames, norm);
    Ok(sum / pairs as f64)
}

fn check_set(name: &'static str, set: &[[f32; 3]]) -> Result<()> {
    if set.is_empty() {
        return Err(EvalError::EmptySet { name });
    }
    match set.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(i) => Err(EvalError::NonFinite {
            name,
            frame: 0,
            vertex: i,
            value: set[i],
        }),
        None => Ok(()),
    }
}

/// (E2) for one frame: `mean_{b∈g} min_{a∈p} ‖a − b‖ + mean_{a∈p} min_{b∈g} ‖a − b‖` with exact nearest neighbours
/// (up to f32 rounding of the distances that choose them, see the `nearest` module). The sets may have different
/// sizes; coordinates beyond ±1e18 are refused.
///
/// # Shapes
/// `p`: `[N_p, 3]`, `g`: `[N_g, 3]`.
pub fn chamfer_sets(p: &[[f32; 3]], g: &[[f32; 3]]) -> Result<f64> {
    check_set("prediction set", p)?;
    check_set("ground-truth set", g)?;
    Ok(mean_nearest(g, p, false)? + mean_nearest(p, g, false)?) // (E2), one frame
}

/// (E2) Chamfer distance averaged over the listed frames; frames run in parallel (rayon), summed in order.
/// Coordinates beyond ±1e18 are refused (see the `nearest` module).
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; `frames`: `[U]`.
pub fn chamfer(pred: Motion, gt: Motion, frames: &[usize]) -> Result<f64> {
    check_pair(pred, gt)?;
    check_frames("scored frame", frames, pred.frames)?;
    let per_frame: Vec<f64> = frames
        .par_iter()
        .map(|&t| Ok(mean_nearest(gt.frame(t), pred.frame(t), true)? + mean_nearest(pred.frame(t), gt.frame(t), true)?))
        .collect::<Result<_>>()?;
    Ok(per_frame.iter().sum::<f64>() / frames.len() as f64) // (E2)
}

/// Per-frame vertex centroids `c_f = mean_v x_{f,v}` of the listed frames, in f64.
///
/// # Shapes
/// `motion`: `[T, N, 3]`; `frames`: `[U]`; returns `[U, 3]`.
pub fn centroids(motion: Motion, frames: &[usize]) -> Vec<[f64; 3]> {
    frames
        .iter()
        .map(|&t| {
            let mut c = [0.0f64; 3];
            for p in motion.frame(t) {
                for k in 0..3 {
                    c[k] += f64::from(p[k]);
                }
            }
            c.map(|x| x / motion.n_vertices as f64)
        })
        .collect()
}

/// The optimal warping path of [`dtw_path`].
#[derive(Debug, Clone, PartialEq)]
pub struct DtwPath {
    /// Minimum summed local cost from (0, 0) to (n − 1, m − 1).
    pub cost: f64,
    /// Index pairs (i, j) of the path π*, from (0, 0) to (n − 1, m − 1).
    pub path: Vec<(usize, usize)>,
}

impl DtwPath {
    /// (E3) the summed cost normalised by the path length |π*|.
    pub fn normalised(&self) -> f64 {
        self.cost / self.path.len() as f64
    }
}

/// Dynamic time warping between two point sequences with local cost ‖a_i − b_j‖₂, steps (1,0), (0,1), (1,1), and
/// minimum **summed** cost. Backtracking breaks ties: diagonal, then (i − 1, j), then (i, j − 1) (docs/method.md (E3)).
///
/// # Shapes
/// `a`: `[n, 3]`, `b`: `[m, 3]`.
pub fn dtw_path(a: &[[f64; 3]], b: &[[f64; 3]]) -> Result<DtwPath> {
    if a.is_empty() || b.is_empty() {
        return Err(EvalError::NoFrames(format!(
            "DTW of sequences of lengths {} and {}",
            a.len(),
            b.len()
        )));
    }
    let (n, m) = (a.len(), b.len());
    let cost = |i: usize, j: usize| norm([a[i][0] - b[j][0], a[i][1] - b[j][1], a[i][2] - b[j][2]]);
    let mut acc = vec![f64::INFINITY; n * m];
    for i in 0..n {
        for j in 0..m {
            let best = if i == 0 && j == 0 {
                0.0
            } else {
                let diag = if i > 0 && j > 0 {
                    acc[(i - 1) * m + j - 1]
                } else {
                    f64::INFINITY
                };
                let up = if i > 0 { acc[(i - 1) * m + j] } else { f64::INFINITY };
                let left = if j > 0 { acc[i * m + j - 1] } else { f64::INFINITY };
                diag.min(up).min(left)
            };
            acc[i * m + j] = cost(i, j) + best;
        }
    }
    let (mut i, mut j) = (n - 1, m - 1);
    let mut path = vec![(i, j)];
    while (i, j) != (0, 0) {
        (i, j) = if i == 0 {
            (0, j - 1)
        } else if j == 0 {
            (i - 1, 0)
        } else {
            // Tie order: diagonal, then (i − 1, j), then (i, j − 1): a later candidate must be strictly smaller.
            let mut next = (i - 1, j - 1);
            for cand in [(i - 1, j), (i, j - 1)] {
                if acc[cand.0 * m + cand.1] < acc[next.0 * m + next.1] {
                    next = cand;
                }
            }
            next
        };
        path.push((i, j));
    }
    path.reverse();
    Ok(DtwPath {
        cost: acc[n * m - 1],
        path,
    })
}

/// (E3) centroid DTW over the listed frames (re-indexed 0..U − 1 in list order): summed cost of π* / |π*|.
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; `frames`: `[U]`.
pub fn centroid_dtw(pred: Motion, gt: Motion, frames: &[usize]) -> Result<f64> {
    check_pair(pred, gt)?;
    check_frames("scored frame", frames, pred.frames)?;
    Ok(dtw_path(&centroids(pred, frames), &centroids(gt, frames))?.normalised()) // (E3)
}

/// Mean over frames f and vertices v of ‖Σ_k w_k x_{f+k,v}‖ · scale: the shared core of (E5) and (E6).
fn mean_difference_norm(motion: Motion, weights: &[f64], scale: f64) -> f64 {
    let windows = motion.frames + 1 - weights.len();
    let mut sum = 0.0;
    for f in 0..windows {
        for v in 0..motion.n_vertices {
            let mut d = [0.0f64; 3];
            for (k, w) in weights.iter().enumerate() {
                let p = motion.vertices[(f + k) * motion.n_vertices + v];
                for c in 0..3 {
                    d[c] += w * f64::from(p[c]);
                }
            }
            sum += norm(d);
        }
    }
    sum * scale / (windows * motion.n_vertices) as f64
}

fn check_rate(rate: f64) -> Result<()> {
    if rate.is_finite() && rate > 0.0 {
        Ok(())
    } else {
        Err(EvalError::Parameter {
            name: "frame rate",
            reason: format!("{rate} is not a positive finite number"),
        })
    }
}

fn check_single(motion: Motion, metric: &'static str, needed: usize) -> Result<()> {
    motion.check("sequence")?;
    if motion.frames < needed {
        return Err(EvalError::TooFewFrames {
            metric,
            needed,
            frames: motion.frames,
        });
    }
    Ok(())
}

/// (E5) mean acceleration norm, `a_f = (x_{f+2} − 2x_{f+1} + x_f)·r²`, averaged over f = 0..T − 3 and v.
///
/// # Shapes
/// `motion`: `[T, N, 3]`, T ≥ 3.
pub fn acceleration(motion: Motion, rate: f64) -> Result<f64> {
    check_rate(rate)?;
    check_single(motion, "acceleration", 3)?;
    Ok(mean_difference_norm(motion, &[1.0, -2.0, 1.0], rate * rate)) // (E5) a_f
}

/// (E5) mean jerk norm, `j_f = (x_{f+3} − 3x_{f+2} + 3x_{f+1} − x_f)·r³`, averaged over f = 0..T − 4 and v.
///
/// # Shapes
/// `motion`: `[T, N, 3]`, T ≥ 4.
pub fn jerk(motion: Motion, rate: f64) -> Result<f64> {
    check_rate(rate)?;
    check_single(motion, "jerk", 4)?;
    Ok(mean_difference_norm(
        motion,
        &[-1.0, 3.0, -3.0, 1.0],
        rate * rate * rate,
    )) // (E5) j_f
}

/// (E6) motion energy: mean over f = 0..T − 2 and v of ‖x_{f+1} − x_f‖.
///
/// # Shapes
/// `motion`: `[T, N, 3]`, T ≥ 2.
pub fn motion_energy(motion: Motion) -> Result<f64> {
    check_single(motion, "motion energy", 2)?;
    Ok(mean_difference_norm(motion, &[-1.0, 1.0], 1.0)) // (E6)
}

/// (E4) VAE reconstruction error: (E1) and (E2) over all frames, and the (E5) jerk of the decoded sequence and of
/// its input, which says how much frame-to-frame noise the VAE alone adds (a floor for every latent method on it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reconstruction {
    pub rmse: f64,
    pub chamfer: f64,
    /// (E5) mean jerk norm of the decoded sequence (per frame, r = 1); NaN below 4 frames.
    pub jerk: f64,
    /// (E5) mean jerk norm of the input; NaN below 4 frames.
    pub jerk_gt: f64,
}

/// (E4) RMSE and Chamfer of a decoded sequence against its input over all frames (no keyframes, no normalisation:
/// both are already in the clip's normalised frame), and both sequences' (E5) jerk.
///
/// # Shapes
/// `decoded`, `input`: `[T, N, 3]`.
pub fn vae_reconstruction(decoded: Motion, input: Motion) -> Result<Reconstruction> {
    let all: Vec<usize> = (0..input.frames).collect();
    let jerk_or_nan = |m: Motion| if m.frames >= 4 { jerk(m, 1.0) } else { Ok(f64::NAN) };
    Ok(Reconstruction {
        rmse: rmse(decoded, input, &all)?,
        chamfer: chamfer(decoded, input, &all)?,
        jerk: jerk_or_nan(decoded)?,
        jerk_gt: jerk_or_nan(input)?,
    }) // (E4), (E5)
}

/// Sorted, deduplicated keyframes, checked against `frames`. An empty set is an error: the protocol always keeps
/// frames 0 and T − 1 (docs/method.md §6.1, §9 item 21).
pub fn keyframe_set(keyframes: &[usize], frames: usize) -> Result<Vec<usize>> {
    check_frames("keyframe", keyframes, frames)?;
    let mut set = keyframes.to_vec();
    set.sort_unstable();
    set.dedup();
    Ok(set)
}

/// The scored frames 𝒰 = {0..T − 1} \ 𝒦 (docs/method.md §6.1), ascending. Errors when every frame is a keyframe.
pub fn non_keyframes(frames: usize, keyframes: &[usize]) -> Result<Vec<usize>> {
    let set = keyframe_set(keyframes, frames)?;
    let scored: Vec<usize> = (0..frames).filter(|f| set.binary_search(f).is_err()).collect();
    if scored.is_empty() {
        return Err(EvalError::NoFrames(format!(
            "all {frames} frames are keyframes {set:?}"
        )));
    }
    Ok(scored)
}

/// The assembled sequence: the prediction with its keyframes replaced by ground truth (docs/method.md §6.1).
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; returns `[T * N]` rows.
pub fn replace_keyframes(pred: Motion, gt: Motion, keyframes: &[usize]) -> Result<Vec<[f32; 3]>> {
    check_pair(pred, gt)?;
    let set = keyframe_set(keyframes, gt.frames)?;
    let mut out = pred.vertices.to_vec();
    let n = gt.n_vertices;
    for f in set {
        out[f * n..(f + 1) * n].copy_from_slice(gt.frame(f));
    }
    Ok(out)
}

/// Normalises prediction and ground truth with (D1)–(D3) computed from ground-truth frame 0 (docs/method.md §6.1).
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]`; returns both as `[T * N]` rows.
pub fn normalise_by_gt(pred: Motion, gt: Motion) -> Result<(Rows, Rows)> {
    check_pair(pred, gt)?;
    let norm = Normalization::from_frame(gt.frame(0)); // (D1), (D2) from GT frame 0
    let (c, s) = (norm.center, norm.scale);
    let apply = |m: Motion| {
        m.vertices
            .iter()
            .map(|p| [0, 1, 2].map(|k| (p[k] - c[k]) / s))
            .collect::<Vec<[f32; 3]>>() // (D3)
    };
    Ok((apply(pred), apply(gt)))
}

/// Which coordinate frame the metrics are computed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Coordinates {
    /// (D1)–(D3) from ground-truth frame 0, applied to both sequences (docs/method.md §6.1; the default).
    #[default]
    NormaliseByGtFrame0,
    /// Use the coordinates as given (the caller has already normalised).
    AsGiven,
}

/// How one clip is scored: the coordinate frame of every metric and the frame rate of (E5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Scoring {
    /// Coordinate frame of every metric.
    pub coordinates: Coordinates,
    /// Frame rate r of (E5) (1 = per frame; 10 matches the 10 FPS renders).
    pub rate: f64,
}

impl Default for Scoring {
    fn default() -> Self {
        Self {
            coordinates: Coordinates::NormaliseByGtFrame0,
            rate: 1.0,
        }
    }
}

/// Every metric of one clip (docs/method.md §6.2), raw values (not × 100).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClipMetrics {
    /// (E1) RMSE over 𝒰.
    pub rmse: f64,
    /// (E1) as printed: mean absolute element error over 𝒰.
    pub mae_elem: f64,
    /// (E2) Chamfer distance over 𝒰.
    pub chamfer: f64,
    /// (E3) centroid DTW over 𝒰.
    pub dtw: f64,
    /// (E5) mean jerk norm of the assembled prediction (all frames).
    pub jerk: f64,
    /// (E5) mean jerk norm of the ground truth.
    pub jerk_gt: f64,
    /// jerk / jerk_gt (infinite or NaN for a static ground truth).
    pub jerk_ratio: f64,
    /// (E5) mean acceleration norm of the assembled prediction.
    pub accel: f64,
    /// (E5) mean acceleration norm of the ground truth.
    pub accel_gt: f64,
    /// accel / accel_gt.
    pub accel_ratio: f64,
    /// (E6) motion energy of the assembled prediction.
    pub energy: f64,
    /// (E6) motion energy of the ground truth.
    pub energy_gt: f64,
    /// (E6) energy / energy_gt: ≪ 1 flags frozen output, ≫ 1 jitter.
    pub energy_ratio: f64,
    /// (E7) RMSE on the keyframes of the prediction before ground-truth replacement.
    pub keyframe_rmse: f64,
    /// Mean per-vertex Euclidean error over 𝒰 (docs/method.md §9 item 14 bounds: dtw ≤ this ≤ √3·rmse, chamfer ≤
    /// 2·this).
    pub mean_vertex_error: f64,
}

/// [`evaluate_clip_with`] under the default scoring (normalise by GT frame 0, r = 1).
pub fn evaluate_clip(pred: Motion, gt: Motion, keyframes: &[usize]) -> Result<ClipMetrics> {
    evaluate_clip_with(pred, gt, keyframes, &Scoring::default())
}

/// Scores one clip by docs/method.md §6.1: coordinates per `scoring`, keyframe error (E7) before replacement, then
/// keyframes replaced by ground truth, (E1)–(E3) over 𝒰 and (E5)–(E6) over the whole assembled sequence.
///
/// # Shapes
/// `pred`, `gt`: `[T, N, 3]` with T ≥ 4 (jerk); `keyframes`: indices into `0..T`.
pub fn evaluate_clip_with(pred: Motion, gt: Motion, keyframes: &[usize], scoring: &Scoring) -> Result<ClipMetrics> {
    check_pair(pred, gt)?;
    check_rate(scoring.rate)?;
    if gt.frames < 4 {
        return Err(EvalError::TooFewFrames {
            metric: "jerk",
            needed: 4,
            frames: gt.frames,
        });
    }
    let (t, n) = (gt.frames, gt.n_vertices);
    let keys = keyframe_set(keyframes, t)?;
    let scored = non_keyframes(t, &keys)?;
    let normalised;
    let (pred, gt) = match scoring.coordinates {
        Coordinates::NormaliseByGtFrame0 => {
            normalised = normalise_by_gt(pred, gt)?;
            (Motion::new(&normalised.0, t, n)?, Motion::new(&normalised.1, t, n)?)
        }
        Coordinates::AsGiven => (pred, gt),
    };
    let keyframe_rmse = rmse(pred, gt, &keys)?; // (E7), before replacement
    let assembled_rows = replace_keyframes(pred, gt, &keys)?;
    let assembled = Motion::new(&assembled_rows, t, n)?;
    let (jerk_p, jerk_g) = (jerk(assembled, scoring.rate)?, jerk(gt, scoring.rate)?);
    let (accel_p, accel_g) = (acceleration(assembled, scoring.rate)?, acceleration(gt, scoring.rate)?);
    let (energy_p, energy_g) = (motion_energy(assembled)?, motion_energy(gt)?);
    Ok(ClipMetrics {
        rmse: rmse(assembled, gt, &scored)?,
        mae_elem: mae_elem(assembled, gt, &scored)?,
        chamfer: chamfer(assembled, gt, &scored)?,
        dtw: centroid_dtw(assembled, gt, &scored)?,
        jerk: jerk_p,
        jerk_gt: jerk_g,
        jerk_ratio: jerk_p / jerk_g,
        accel: accel_p,
        accel_gt: accel_g,
        accel_ratio: accel_p / accel_g,
        energy: energy_p,
        energy_gt: energy_g,
        energy_ratio: energy_p / energy_g,
        keyframe_rmse,
        mean_vertex_error: mean_vertex_error(assembled, gt, &scored)?,
    })
}

/// Field-wise mean over clips (docs/method.md §6.1: each metric per clip, then averaged; ratios are averaged per clip
/// too).
pub fn average(clips: &[ClipMetrics]) -> Result<ClipMetrics> {
    if clips.is_empty() {
        return Err(EvalError::NoClips);
    }
    let mean = |f: fn(&ClipMetrics) -> f64| clips.iter().map(f).sum::<f64>() / clips.len() as f64;
    Ok(ClipMetrics {
        rmse: mean(|c| c.rmse),
        mae_elem: mean(|c| c.mae_elem),
        chamfer: mean(|c| c.chamfer),
        dtw: mean(|c| c.dtw),
        jerk: mean(|c| c.jerk),
        jerk_gt: mean(|c| c.jerk_gt),
        jerk_ratio: mean(|c| c.jerk_ratio),
        accel: mean(|c| c.accel),
        accel_gt: mean(|c| c.accel_gt),
        accel_ratio: mean(|c| c.accel_ratio),
        energy: mean(|c| c.energy),
        energy_gt: mean(|c| c.energy_gt),
        energy_ratio: mean(|c| c.energy_ratio),
        keyframe_rmse: mean(|c| c.keyframe_rmse),
        mean_vertex_error: mean(|c| c.mean_vertex_error),
    })
}
