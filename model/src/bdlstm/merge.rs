//! The BD-LSTM completion merge rule for one segment between consecutive keyframes a < b: run both chains,
//! find the aligned pair where they agree best, switch from the forward chain to the backward one there, and
//! retry with perturbed initial states until the pair is closer than the threshold (the paper's "5 %").

use burn::prelude::*;

/// Settings of the merge rule.
#[derive(Config, Debug)]
pub struct MergeConfig {
    /// A try is accepted when its smallest aligned distance d_i is below this (fraction of the bbox diagonal).
    #[config(default = 0.05)]
    pub threshold: f64,
    /// Tries in all (the first with the nominal initial states); if none passes, the best one is used.
    #[config(default = 8)]
    pub max_tries: usize,
}

/// Why a try cannot be merged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SegmentError {
    /// The chains or distances disagree in length.
    #[error("segment try: forward has {forward} frames, backward {backward}, distances {distances} (all must match)")]
    Length {
        forward: usize,
        backward: usize,
        distances: usize,
    },
    /// A segment needs at least one frame to fill between its keyframes.
    #[error("segment try: {frames} frames, a segment a..=b with a missing frame has at least 3")]
    TooShort { frames: usize },
    /// The two frames of a pair have different vertex counts.
    #[error("segment distance: forward frame has {forward} vertices, backward {backward}")]
    Vertices { forward: usize, backward: usize },
    /// `max_tries` is zero.
    #[error("merge rule: max_tries must be at least 1")]
    NoTries,
}

/// Both chains of one try, each in time order a..=b (the backward chain already reversed), with d_i per frame.
#[derive(Debug, Clone)]
pub struct SegmentTry<T> {
    forward: Vec<T>,
    backward: Vec<T>,
    distances: Vec<f64>,
}

impl<T> SegmentTry<T> {
    /// Checks that the three sequences have one entry per frame of a..=b and at least 3 frames.
    ///
    /// # Errors
    /// [`SegmentError::Length`] or [`SegmentError::TooShort`].
    pub fn new(forward: Vec<T>, backward: Vec<T>, distances: Vec<f64>) -> Result<Self, SegmentError> {
        if forward.len() != backward.len() || forward.len() != distances.len() {
            return Err(SegmentError::Length {
                forward: forward.len(),
                backward: backward.len(),
                distances: distances.len(),
            });
        }
        if forward.len() < 3 {
            return Err(SegmentError::TooShort { frames: forward.len() });
        }
        Ok(Self {
            forward,
            backward,
            distances,
        })
    }

    /// (index, d) of the smallest distance, the earliest on ties; NaN counts as +∞.
    pub fn best_pair(&self) -> (usize, f64) {
        let key = |d: f64| if d.is_nan() { f64::INFINITY } else { d };
        self.distances.iter().enumerate().fold(
            (0, f64::INFINITY),
            |(bi, bd), (i, &d)| if key(d) < bd { (i, key(d)) } else { (bi, bd) },
        )
    }
}

/// The merged segment.
#[derive(Debug, Clone)]
pub struct MergedSegment<T> {
    /// Frames a..=b: forward up to `split` (inclusive), backward after it.
    pub frames: Vec<T>,
    /// Index (from a) of the last forward frame, the argmin i* of d_i.
    pub split: usize,
    /// d at the split.
    pub distance: f64,
    /// Tries run.
    pub tries: usize,
    /// Whether the distance passed the threshold (otherwise the best of all tries was used).
    pub accepted: bool,
}

/// Runs `attempt(0)`, `attempt(1)`, … (attempt 0 with the nominal initial states, later ones perturbed) until a
/// try's smallest d_i is below the threshold, at most `max_tries` times, and merges the accepted try (or the one
/// with the smallest d): frames a..a+i* from the forward chain, the rest from the backward chain.
///
/// # Errors
/// [`SegmentError::NoTries`], or the first error of `attempt`.
pub fn merge_segment<T, E: From<SegmentError>>(
    cfg: &MergeConfig,
    mut attempt: impl FnMut(usize) -> Result<SegmentTry<T>, E>,
) -> Result<MergedSegment<T>, E> {
    if cfg.max_tries == 0 {
        return Err(SegmentError::NoTries.into());
    }
    let mut best: Option<(SegmentTry<T>, usize, f64)> = None;
    let mut tries = 0;
    for k in 0..cfg.max_tries {
        let t = attempt(k)?;
        tries = k + 1;
        let (i, d) = t.best_pair();
        let better = best.as_ref().is_none_or(|(_, _, bd)| d < *bd);
        if better {
            best = Some((t, i, d));
        }
        if d < cfg.threshold {
            break;
        }
    }
    let (t, split, distance) = best.expect("max_tries ≥ 1 ran at least one try");
    let frames = t
        .forward
        .into_iter()
        .zip(t.backward)
        .enumerate()
        .map(|(i, (f, b))| if i <= split { f } else { b })
        .collect();
    Ok(MergedSegment {
        frames,
        split,
        distance,
        tries,
        accepted: distance < cfg.threshold,
    })
}

/// Diagonal of the axis-aligned bounding box of a frame.
pub fn bbox_diagonal(frame: &[[f32; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in frame {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    if frame.is_empty() {
        return 0.0;
    }
    (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
}

/// d = mean_v ‖x^f_v − x^b_v‖ / diag, with the diagonal floored at 1e-12 (a frame collapsed to a point); 0 for
/// empty frames.
///
/// # Errors
/// [`SegmentError::Vertices`] when the frames differ in length.
///
/// # Shapes
/// - `forward`, `backward`: `[N]` xyz each
pub fn frame_distance(forward: &[[f32; 3]], backward: &[[f32; 3]], diag: f64) -> Result<f64, SegmentError> {
    let n = forward.len();
    if backward.len() != n {
        return Err(SegmentError::Vertices {
            forward: n,
            backward: backward.len(),
        });
    }
    if n == 0 {
        return Ok(0.0);
    }
    let sum: f64 = forward
        .iter()
        .zip(backward)
        .map(|(a, b)| (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum::<f64>().sqrt())
        .sum();
    Ok(sum / n as f64 / diag.max(1e-12))
}
