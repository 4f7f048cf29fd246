//! Linear scaling of ACAP features to [−0.95, 0.95] (the range the BD-LSTM's tanh layers work in), fitted on a
//! training set and stored beside the model so that generated features can be mapped back.

use serde::{Deserialize, Serialize};

use super::{ACAP_CHANNELS, AcapFrame};
use crate::error::{DataError, Result};

/// Bound of the scaled features.
pub const SCALE_BOUND: f32 = 0.95;
/// Smallest half-range of a channel; a channel that never varies is centred, not divided by zero.
pub const MIN_HALF_RANGE: f32 = 1e-6;

/// Which minima and maxima the scaling uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScalingGranularity {
    /// One range per channel, over all vertices and frames (9 ranges).
    PerChannel,
    /// One range per vertex and channel, over all frames (N × 9 ranges; needs one fixed topology).
    PerVertexChannel,
}

/// x_scaled = 0.95 · (x − mid) / half with mid, half the centre and half-width of the fitted range
/// (half ≥ [`MIN_HALF_RANGE`]); the inverse maps any value back linearly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcapScaling {
    /// How the ranges were taken.
    pub granularity: ScalingGranularity,
    /// Centre of each range: one row, or one per vertex.
    pub mid: Vec<[f32; ACAP_CHANNELS]>,
    /// Half-width of each range, same layout as `mid`.
    pub half: Vec<[f32; ACAP_CHANNELS]>,
}

impl AcapScaling {
    /// Fits the ranges on `frames` (all of one topology for [`ScalingGranularity::PerVertexChannel`]).
    ///
    /// # Errors
    /// No frames, frames of different vertex counts (per-vertex ranges), or a non-finite feature.
    pub fn fit(frames: &[AcapFrame], granularity: ScalingGranularity) -> Result<Self> {
        let err = |field: &str, reason: String| DataError::new("acap scaling", field, reason);
        let Some(first) = frames.first() else {
            return Err(err("frames", "no frames to fit the scaling on".into()));
        };
        let rows = match granularity {
            ScalingGranularity::PerChannel => 1,
            ScalingGranularity::PerVertexChannel => first.len(),
        };
        let mut lo = vec![[f32::INFINITY; ACAP_CHANNELS]; rows];
        let mut hi = vec![[f32::NEG_INFINITY; ACAP_CHANNELS]; rows];
        for (f, frame) in frames.iter().enumerate() {
            if granularity == ScalingGranularity::PerVertexChannel && frame.len() != rows {
                return Err(err(
                    "frames",
                    format!(
                        "frame {f} has {} vertices, frame 0 {rows}: per-vertex ranges need one topology",
                        frame.len()
                    ),
                ));
            }
            for (v, x) in frame.iter().enumerate() {
                let row = if rows == 1 { 0 } else { v };
                for c in 0..ACAP_CHANNELS {
                    if !x[c].is_finite() {
                        return Err(err(
                            "features",
                            format!("non-finite feature at frame {f}, vertex {v}, channel {c}"),
                        ));
                    }
                    lo[row][c] = lo[row][c].min(x[c]);
                    hi[row][c] = hi[row][c].max(x[c]);
                }
            }
        }
        if lo[0][0] > hi[0][0] {
            return Err(err("frames", "the frames hold no vertices".into()));
        }
        let mid = lo
            .iter()
            .zip(&hi)
            .map(|(l, h)| std::array::from_fn(|c| 0.5 * (l[c] + h[c])))
            .collect();
        let half = lo
            .iter()
            .zip(&hi)
            .map(|(l, h)| std::array::from_fn(|c| (0.5 * (h[c] - l[c])).max(MIN_HALF_RANGE)))
            .collect();
        Ok(Self { granularity, mid, half })
    }

    fn row(&self, frame: &[[f32; ACAP_CHANNELS]]) -> Result<impl Fn(usize) -> usize> {
        let rows = self.mid.len();
        if self.granularity == ScalingGranularity::PerVertexChannel && frame.len() != rows {
            return Err(DataError::new(
                "acap scaling",
                "features",
                format!("{} vertices, the scaling was fitted on {rows}", frame.len()),
            ));
        }
        Ok(move |v: usize| if rows == 1 { 0 } else { v })
    }

    /// Features mapped into [−0.95, 0.95] (values outside the fitted range land outside it, linearly).
    ///
    /// # Errors
    /// A vertex count other than the fitted one for per-vertex ranges.
    pub fn scale(&self, frame: &[[f32; ACAP_CHANNELS]]) -> Result<AcapFrame> {
        let row = self.row(frame)?;
        Ok(frame
            .iter()
            .enumerate()
            .map(|(v, x)| {
                let (m, h) = (&self.mid[row(v)], &self.half[row(v)]);
                std::array::from_fn(|c| SCALE_BOUND * (x[c] - m[c]) / h[c])
            })
            .collect())
    }

    /// The inverse of [`AcapScaling::scale`].
    ///
    /// # Errors
    /// A vertex count other than the fitted one for per-vertex ranges.
    pub fn unscale(&self, frame: &[[f32; ACAP_CHANNELS]]) -> Result<AcapFrame> {
        let row = self.row(frame)?;
        Ok(frame
            .iter()
            .enumerate()
            .map(|(v, x)| {
                let (m, h) = (&self.mid[row(v)], &self.half[row(v)]);
                std::array::from_fn(|c| m[c] + h[c] * x[c] / SCALE_BOUND)
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(rows: &[[f32; 2]]) -> AcapFrame {
        rows.iter()
            .map(|r| std::array::from_fn(|c| r[c % 2] * (c + 1) as f32))
            .collect()
    }

    #[test]
    fn per_channel_maps_the_range_to_the_bound_and_back() {
        let frames = vec![frame(&[[1.0, 3.0], [2.0, 3.0]]), frame(&[[-1.0, 3.0], [0.0, 3.0]])];
        let s = AcapScaling::fit(&frames, ScalingGranularity::PerChannel).unwrap();
        // Channel 0 spans [−1, 2]: −1 → −0.95, 2 → 0.95, 0.5 → 0.
        let scaled = s.scale(&frames[0]).unwrap();
        assert!((scaled[1][0] - 0.95).abs() < 1e-6 && (s.scale(&frames[1]).unwrap()[0][0] + 0.95).abs() < 1e-6);
        // Channel 1 is constant 3: centred at 0, no division by zero.
        assert_eq!(scaled[0][1], 0.0);
        for f in &frames {
            let back = s.unscale(&s.scale(f).unwrap()).unwrap();
            for (a, b) in back.iter().flatten().zip(f.iter().flatten()) {
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn per_vertex_ranges_and_bad_input() {
        let frames = vec![frame(&[[1.0, 0.0], [5.0, 0.0]]), frame(&[[3.0, 0.0], [9.0, 0.0]])];
        let s = AcapScaling::fit(&frames, ScalingGranularity::PerVertexChannel).unwrap();
        let scaled = s.scale(&frames[1]).unwrap();
        assert!((scaled[0][0] - 0.95).abs() < 1e-6 && (scaled[1][0] - 0.95).abs() < 1e-6);
        let e = s.scale(&frame(&[[1.0, 0.0]])).unwrap_err();
        assert!(e.reason.contains("fitted on 2"), "{e}");
        let e = AcapScaling::fit(&[], ScalingGranularity::PerChannel).unwrap_err();
        assert_eq!(e.field, "frames");
        let e = AcapScaling::fit(&[frame(&[[f32::NAN, 0.0]])], ScalingGranularity::PerChannel).unwrap_err();
        assert!(e.reason.contains("non-finite"), "{e}");
    }
}
