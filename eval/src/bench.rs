//! What `any4d bench metrics` measures: the per-clip metrics (E1)–(E7) of docs/method.md §6.2 on synthetic clips,
//! averaged over clips, on the current rayon pool; the numpy/scipy reference (`scripts/metrics_reference.py`) reads
//! the same clips from the file [`write_f32_clips`] writes.

use std::path::Path;
use std::time::Instant;

use any4d_data::rng::{DataRng, Rng, SeedableRng};
use any4d_model::bench::median;
use rayon::prelude::*;

use crate::metrics::{ClipMetrics, Motion, Rows, Scoring, average, evaluate_clip_with};

use crate::error::{EvalError, Result};

/// Sizes of the benchmark clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MetricsBench {
    /// Number of clips.
    pub clips: usize,
    /// Vertices per clip.
    pub vertices: usize,
    /// Frames per clip (≥ 4 for jerk).
    pub frames: usize,
}

impl MetricsBench {
    /// Checks the sizes; the error names the options.
    pub fn check(&self) -> Result<()> {
        if self.frames < 4 || self.vertices == 0 || self.clips == 0 {
            return Err(EvalError::invalid(
                "bench metrics",
                "sizes",
                "--frames must be ≥ 4 (jerk), --vertices and --clips ≥ 1",
            ));
        }
        Ok(())
    }

    /// The keyframes of every clip: first and last.
    pub fn keyframes(&self) -> Vec<usize> {
        vec![0, self.frames - 1]
    }

    /// Synthetic clips: a random cloud moving smoothly, and a noisy prediction. `(prediction, ground truth)`,
    /// rows `[T · N]` each, the same for every call.
    pub fn clips(&self) -> Vec<(Rows, Rows)> {
        let mut rng = DataRng::seed_from_u64(0);
        (0..self.clips)
            .map(|_| {
                let base: Vec<[f32; 3]> = (0..self.vertices)
                    .map(|_| [0; 3].map(|_| rng.random_range(-1.0f32..1.0)))
                    .collect();
                let vel: [f32; 3] = [0; 3].map(|_| rng.random_range(-0.05f32..0.05));
                let gt: Vec<[f32; 3]> = (0..self.frames)
                    .flat_map(|f| base.iter().map(move |b| [0, 1, 2].map(|k| b[k] + vel[k] * f as f32)))
                    .collect();
                let pred = gt
                    .iter()
                    .map(|g| [0, 1, 2].map(|k| g[k] + rng.random_range(-0.02f32..0.02)))
                    .collect();
                (pred, gt)
            })
            .collect()
    }

    /// The mean metrics over `clips` (each clip scored on the current rayon pool).
    pub fn score(&self, clips: &[(Rows, Rows)]) -> Result<ClipMetrics> {
        let keys = self.keyframes();
        let scoring = Scoring::default();
        let err = |e: crate::metrics::EvalError| EvalError::invalid("bench metrics", "clips", e.to_string());
        let per_clip = clips
            .par_iter()
            .map(|(p, g)| {
                let (p, g) = (
                    Motion::new(p, self.frames, self.vertices)?,
                    Motion::new(g, self.frames, self.vertices)?,
                );
                evaluate_clip_with(p, g, &keys, &scoring)
            })
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(err)?;
        average(&per_clip).map_err(err)
    }
}

/// Median seconds of `repeat` (at least one) runs of `f`, and the last result.
pub fn timed<T, E>(
    repeat: usize,
    mut f: impl FnMut() -> std::result::Result<T, E>,
) -> std::result::Result<(f64, T), E> {
    let start = Instant::now();
    let mut last = f()?;
    let mut times = vec![start.elapsed().as_secs_f64()];
    for _ in 1..repeat {
        let start = Instant::now();
        last = f()?;
        times.push(start.elapsed().as_secs_f64());
    }
    Ok((median(&times), last))
}

/// Writes every clip as little-endian f32, prediction then ground truth, for the reference script.
pub fn write_f32_clips(path: &Path, clips: &[(Rows, Rows)]) -> Result<()> {
    let bytes: Vec<u8> = clips
        .iter()
        .flat_map(|(p, g)| p.iter().chain(g))
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    std::fs::write(path, bytes).map_err(|e| EvalError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_clips_score_zero_and_noisy_ones_do_not() {
        let bench = MetricsBench {
            clips: 2,
            vertices: 16,
            frames: 5,
        };
        let clips = bench.clips();
        assert_eq!(clips, bench.clips(), "the clips are deterministic");
        let exact: Vec<(Rows, Rows)> = clips.iter().map(|(_, g)| (g.clone(), g.clone())).collect();
        assert_eq!(bench.score(&exact).expect("scores").rmse, 0.0);
        let noisy = bench.score(&clips).expect("scores").rmse;
        assert!(noisy > 0.0 && noisy < 0.02, "{noisy}");
        assert!(MetricsBench { frames: 3, ..bench }.check().is_err());
    }

    #[test]
    fn timed_reports_the_median_and_the_last_result() {
        let mut calls = 0;
        let (secs, last) = timed(3, || -> Result<usize> {
            calls += 1;
            Ok(calls)
        })
        .expect("runs");
        assert_eq!((calls, last), (3, 3));
        assert!(secs >= 0.0);
        let failing = timed(2, || -> Result<()> { Err(EvalError::invalid("x", "y", "z")) });
        assert!(failing.is_err());
    }
}
