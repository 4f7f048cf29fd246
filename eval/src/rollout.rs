//! Long-horizon generation (docs/method.md §7, P-Eq. 18–21): 16-frame windows every 15 frames sharing one frame,
//! each re-normalised by its overlap frame (H1)–(H2), generated, de-normalised (H3) and stitched half-open (H4).
//!
//! Generic over a window generator, so any completion method (or a test double) drives it.

use crate::error::{EvalError, Result};

/// Which mesh is the reference (local frame 0) of windows after the first (docs/method.md §7 step 4, §8 A8).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OverlapSource {
    /// The ground-truth mesh at the shared frame, when that frame is a keyframe (default for keyframe methods);
    /// a shared frame that is not a keyframe falls back to the generated one.
    #[default]
    GroundTruth,
    /// The previous window's output at the shared frame (autoregressive; P-Table 2's default, every row alike).
    Generated,
}

impl OverlapSource {
    /// One line for a table's header.
    pub fn describe(self) -> &'static str {
        match self {
            OverlapSource::Generated => "stage-2 reference: each row's own generated overlap frame (every row alike)",
            OverlapSource::GroundTruth => {
                "stage-2 reference: the ground-truth overlap frame where it is a keyframe (`--overlap-source gt`: \
                 favours rows that are given keyframes over the AnimateAnyMesh row, which has none)"
            }
        }
    }
}

/// Window layout of a rollout: `window` frames per generation, a new window every `stride` frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RolloutSpec {
    /// Frames per window (T = 16).
    pub window: usize,
    /// Frames between window starts (15: consecutive windows share one frame).
    pub stride: usize,
    /// Reference of windows 1, 2, ….
    pub overlap_source: OverlapSource,
}

impl RolloutSpec {
    /// The paper's layout: 16-frame windows every 15 frames, ground-truth overlap.
    pub fn paper() -> Self {
        Self {
            window: 16,
            stride: 15,
            overlap_source: OverlapSource::GroundTruth,
        }
    }

    /// Window start frames for a sequence of `frames` frames: 0, 15, 30, … while a window still ends before the
    /// last frame; the final window is aligned to end on the last frame (start = frames − window), so any length
    /// ≥ `window` is covered. 31 frames → [0, 15]; 46 → [0, 15, 30]; 40 → [0, 15, 24].
    pub fn starts(&self, frames: usize) -> Result<Vec<usize>> {
        if self.window < 2 || self.stride == 0 || self.stride >= self.window {
            return Err(EvalError::invalid(
                "rollout",
                "spec",
                format!(
                    "window {} / stride {} must satisfy 1 ≤ stride < window, window ≥ 2",
                    self.window, self.stride
                ),
            ));
        }
        if frames < self.window {
            return Err(EvalError::invalid(
                "rollout",
                "frames",
                format!("{frames} frames, a window needs {}", self.window),
            ));
        }
        let mut starts = vec![0];
        let mut s = 0;
        while s + self.window < frames {
            s = (s + self.stride).min(frames - self.window);
            starts.push(s);
        }
        Ok(starts)
    }
}

/// Window statistics (H1): the bounding-box centre c₁ and L∞ half-extent s₁ of the overlap frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowFrame {
    /// c₁.
    pub center: [f32; 3],
    /// s₁ (1 when the half-extent is ≤ 0 or not finite).
    pub scale: f32,
}

impl WindowFrame {
    /// The identity (stage 1 works in the global frame directly, docs/method.md §7 step 1).
    pub const IDENTITY: WindowFrame = WindowFrame {
        center: [0.0; 3],
        scale: 1.0,
    };

    /// (H1) from the vertices of the overlap frame.
    pub fn from_overlap(frame: &[[f32; 3]]) -> Self {
        let (lo, hi) = any4d_data::preprocess::bounds(frame);
        let center = [0, 1, 2].map(|k| {
            if lo[k].is_finite() && hi[k].is_finite() {
                (hi[k] + lo[k]) / 2.0
            } else {
                0.0
            }
        });
        let half = frame
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - center[k]).abs()))
            .fold(0.0f32, f32::max);
        // (H1) c₁ = (max V_ov + min V_ov)/2, s₁ = max |V_ov − c₁|; s₁ = 1 if s₁ ≤ 0 or not finite.
        // A non-finite coordinate makes s₁ non-finite in the paper's arithmetic: fall back to 1 as well.
        let finite = frame.iter().all(|p| p.iter().all(|c| c.is_finite()));
        let scale = if finite && half > 0.0 && half.is_finite() {
            half
        } else {
            1.0
        };
        Self { center, scale }
    }

    /// (H2) V̄ = (V − c₁)/s₁.
    pub fn normalize(&self, p: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|k| (p[k] - self.center[k]) / self.scale)
    }

    /// (H3) V̂ = s₁ · V̄̂ + c₁.
    pub fn denormalize(&self, p: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|k| p[k] * self.scale + self.center[k])
    }
}

/// What a window generator is given: the window in its own normalised frame, with every frame that is not a
/// keyframe hidden (replaced by the local reference, frame 0), the local keyframes and the prompt.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowInput<'a> {
    /// Window number w (0 = stage 1).
    pub index: usize,
    /// First global frame of the window.
    pub start: usize,
    /// `[window, N]` rows of xyz, frame-major, normalised by (H2) (identity for w = 0).
    pub vertices: Vec<[f32; 3]>,
    /// Local keyframe indices, sorted; always contains 0 (the reference mesh).
    pub keyframes: Vec<usize>,
    /// The window's prompt.
    pub caption: &'a str,
}

/// Result of a rollout.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollout {
    /// `[frames, N]` rows of xyz in the global normalised frame, stitched by (H4).
    pub vertices: Vec<[f32; 3]>,
    /// Window start frames (seams are at `starts[1..]`).
    pub starts: Vec<usize>,
    /// (H1) statistics per window (identity for window 0).
    pub frames: Vec<WindowFrame>,
}

/// Run the windowed rollout of docs/method.md §7 over a ground-truth sequence in the global normalised frame.
///
/// `keyframes` are global frame indices (e.g. {0, 15, 30}); each window receives those inside it, re-indexed,
/// plus its local frame 0. `captions` holds one prompt per window, or one prompt for all windows.
/// `generate` returns the window's prediction in the window's frame, `[window, N]` rows.
///
/// # Shapes
/// `gt`: `[T_total, N]` rows of xyz; output `[T_total, N]`.
pub fn rollout<F>(
    gt: &[[f32; 3]],
    n_vertices: usize,
    keyframes: &[usize],
    captions: &[&str],
    spec: RolloutSpec,
    mut generate: F,
) -> Result<Rollout>
where
    F: FnMut(&WindowInput<'_>) -> Result<Vec<[f32; 3]>>,
{
    if n_vertices == 0 || !gt.len().is_multiple_of(n_vertices) {
        return Err(EvalError::invalid(
            "rollout",
            "vertices",
            format!("{} rows are not whole frames of {n_vertices} vertices", gt.len()),
        ));
    }
    let total = gt.len() / n_vertices;
    let starts = spec.starts(total)?;
    if captions.len() != 1 && captions.len() != starts.len() {
        return Err(EvalError::invalid(
            "rollout",
            "captions",
            format!(
                "{} prompts for {} windows: give one per window or one for all",
                captions.len(),
                starts.len()
            ),
        ));
    }
    if let Some(&k) = keyframes.iter().find(|&&k| k >= total) {
        return Err(EvalError::invalid(
            "rollout",
            "keyframes",
            format!("frame {k} is outside 0..{total}"),
        ));
    }
    let frame = |seq: &[[f32; 3]], f: usize| seq[f * n_vertices..(f + 1) * n_vertices].to_vec();
    let mut out = gt.to_vec(); // overwritten window by window; frames before a window's start are final
    let mut stats = Vec::with_capacity(starts.len());
    for (w, &start) in starts.iter().enumerate() {
        // The window's reference mesh: ground truth for stage 1 and for a ground-truth overlap at a keyframe,
        // otherwise the frame the previous window generated (docs/method.md §7 steps 2 and 4).
        let from_gt = w == 0 || (spec.overlap_source == OverlapSource::GroundTruth && keyframes.contains(&start));
        let reference = if from_gt { frame(gt, start) } else { frame(&out, start) };
        let stat = if w == 0 {
            WindowFrame::IDENTITY
        } else {
            WindowFrame::from_overlap(&reference)
        };
        let mut local_kf: Vec<usize> = keyframes
            .iter()
            .filter(|&&k| k >= start && k < start + spec.window)
            .map(|&k| k - start)
            .collect();
        local_kf.push(0);
        local_kf.sort_unstable();
        local_kf.dedup();
        let mut vertices = Vec::with_capacity(spec.window * n_vertices);
        for local in 0..spec.window {
            let src = if local == 0 {
                reference.clone()
            } else if local_kf.contains(&local) {
                frame(gt, start + local)
            } else {
                reference.clone() // hidden frame: the generator must not see ground truth here
            };
            vertices.extend(src.into_iter().map(|p| stat.normalize(p))); // (H2)
        }
        let caption = captions[if captions.len() == 1 { 0 } else { w }];
        let input = WindowInput {
            index: w,
            start,
            vertices,
            keyframes: local_kf,
            caption,
        };
        let pred = generate(&input)?;
        if pred.len() != spec.window * n_vertices {
            return Err(EvalError::invalid(
                "rollout",
                format!("window {w}"),
                format!(
                    "generator returned {} rows, expected {} frames × {n_vertices}",
                    pred.len(),
                    spec.window
                ),
            ));
        }
        if let Some(i) = pred.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(EvalError::invalid(
                "rollout",
                format!("window {w}"),
                format!(
                    "non-finite prediction at local frame {}, vertex {}",
                    i / n_vertices,
                    i % n_vertices
                ),
            ));
        }
        // (H3) de-normalise, (H4) stitch: out[start .. start + window) = this window (half-open; the shared frame
        // `start` is written once, by this window).
        for (i, p) in pred.into_iter().enumerate() {
            out[start * n_vertices + i] = stat.denormalize(p);
        }
        stats.push(stat);
    }
    Ok(Rollout {
        vertices: out,
        starts,
        frames: stats,
    })
}

/// Mean jerk magnitude (E5) in a band of ±`half_width` frames around `seam`: the third differences
/// j_f = (x_{f+3} − 3x_{f+2} + 3x_{f+1} − x_f)·r³ whose four frames all lie in [seam − h, seam + h], averaged over
/// those f and the vertices. Returns `None` when the band holds fewer than four frames of the sequence.
///
/// # Shapes
/// `seq`: `[T, N]` rows of xyz.
pub fn seam_jerk(seq: &[[f32; 3]], n_vertices: usize, seam: usize, half_width: usize, rate: f64) -> Option<f64> {
    let frames = seq.len() / n_vertices.max(1);
    let lo = seam.saturating_sub(half_width);
    let hi = (seam + half_width).min(frames.saturating_sub(1));
    if hi < lo + 3 {
        return None;
    }
    let at = |f: usize, v: usize, k: usize| f64::from(seq[f * n_vertices + v][k]);
    let mut sum = 0.0;
    let mut count = 0usize;
    for f in lo..=hi - 3 {
        for v in 0..n_vertices {
            let norm2: f64 = (0..3)
                .map(|k| {
                    let j =
                        (at(f + 3, v, k) - 3.0 * at(f + 2, v, k) + 3.0 * at(f + 1, v, k) - at(f, v, k)) * rate.powi(3); // (E5)
                    j * j
                })
                .sum();
            sum += norm2.sqrt();
            count += 1;
        }
    }
    Some(sum / count as f64)
}
