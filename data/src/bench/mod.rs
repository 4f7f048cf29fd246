//! What `any4d bench data` measures: reading `.bin` clips, normalising them (docs/method.md (D1)–(D3)) and
//! farthest-point sampling frame 0 (§2.5) on one thread, on deterministic clips that the numpy reference
//! (`scripts/bench_data_reference.py`) reads too; the FPS checksum lets the two implementations be compared.
//! [`readers`] times every reader on the same clips written in its format.

pub mod acap;
pub mod readers;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::formats;
use crate::fps::farthest_point_sampling;
use crate::preprocess;
use crate::rng::{Rng, rng};

/// Sizes of the benchmark clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataBench {
    /// Clips written and read.
    pub clips: usize,
    /// Vertices per clip.
    pub vertices: usize,
    /// Frames per clip.
    pub frames: usize,
    /// FPS tokens P.
    pub p: usize,
}

/// Our side of the benchmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataTiming {
    /// Wall seconds for all clips on one thread.
    pub seconds: f64,
    /// Σ of every FPS index (the reference prints the same sum).
    pub fps_checksum: u64,
}

impl DataBench {
    /// Checks the sizes; the error names the option.
    pub fn check(&self) -> Result<()> {
        if self.clips == 0 || self.vertices < 3 || self.frames < 2 || self.p == 0 {
            return Err(DataError::new(
                "bench data",
                "sizes",
                "needs --clips ≥ 1, --vertices ≥ 3, --frames ≥ 2 and --p ≥ 1",
            ));
        }
        Ok(())
    }

    /// Writes the benchmark clips into `dir` as `clip_NNNNN.bin`; returns their paths.
    pub fn write_clips(&self, dir: &Path) -> Result<Vec<PathBuf>> {
        self.check()?;
        (0..self.clips)
            .map(|i| {
                let path = dir.join(format!("clip_{i:05}.bin"));
                formats::write_clip(&path, &bench_clip(i, self.frames, self.vertices)?)?;
                Ok(path)
            })
            .collect()
    }

    /// Reads, normalises and samples every file on one thread.
    pub fn time(&self, files: &[PathBuf]) -> Result<DataTiming> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| DataError::new("bench data", "threads", e.to_string()))?;
        pool.install(|| {
            let start = Instant::now();
            let mut fps_checksum = 0u64;
            for path in files {
                let clip = formats::read_clip(path)?;
                let (clip, _norm) = preprocess::normalize(&clip); // (D1)–(D3)
                fps_checksum += farthest_point_sampling(clip.frame(0), self.p)
                    .iter()
                    .map(|&i| u64::from(i))
                    .sum::<u64>();
            }
            Ok(DataTiming {
                seconds: start.elapsed().as_secs_f64(),
                fps_checksum,
            })
        })
    }
}

/// A deterministic clip for the benchmark: a noisy sphere of `n` vertices that drifts and breathes over `frames`
/// frames, with a triangle strip.
pub fn bench_clip(index: usize, frames: usize, n: usize) -> Result<Clip> {
    let mut r = rng(index as u64, 0xbe7c);
    let base: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let v = [0, 1, 2].map(|_| r.random_range(-1.0f32..1.0));
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-3);
            v.map(|x| 3.0 * x / len + 0.05 * r.random_range(-1.0f32..1.0))
        })
        .collect();
    let vertices = (0..frames)
        .flat_map(|f| {
            let (s, dx) = (1.0 + 0.02 * f as f32, 0.1 * f as f32);
            base.iter()
                .map(move |p| [p[0] * s + dx, p[1] * s, p[2] * s])
                .collect::<Vec<_>>()
        })
        .collect();
    let faces = (0..n.saturating_sub(2) as u32).map(|i| [i, i + 1, i + 2]).collect();
    Clip::new(
        format!("bench-{index}"),
        vertices,
        frames,
        n,
        faces,
        "a benchmark blob",
        format!("bench:{index}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clips_round_trip_and_the_checksum_is_the_sum_of_fps_indices() {
        let dir = tempfile::tempdir().expect("temp dir");
        let bench = DataBench {
            clips: 2,
            vertices: 40,
            frames: 3,
            p: 5,
        };
        let files = bench.write_clips(dir.path()).expect("written");
        assert_eq!(files.len(), 2);
        let timing = bench.time(&files).expect("timed");
        let expected: u64 = (0..2)
            .map(|i| {
                let (clip, _) = preprocess::normalize(&bench_clip(i, 3, 40).expect("clip"));
                farthest_point_sampling(clip.frame(0), 5)
                    .iter()
                    .map(|&v| u64::from(v))
                    .sum::<u64>()
            })
            .sum();
        assert_eq!(timing.fps_checksum, expected);
        assert!(timing.seconds > 0.0);
        let err = DataBench { clips: 0, ..bench }.check().unwrap_err();
        assert!(err.to_string().contains("--clips ≥ 1"), "{err}");
    }
}
