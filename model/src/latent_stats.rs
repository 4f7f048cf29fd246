//! Global latent standardization (docs/method.md §3.4, AAM code): one scalar mean and standard deviation for all shape
//! entries z₀ and one for all trajectory entries z_f, accumulated over the training set with Welford/Chan
//! merging; the rectified flow works on (z − mean)/std. The train crate stores [`LatentStats`] with the VAE
//! checkpoint.

use burn::prelude::*;
use serde::{Deserialize, Serialize};

/// Scalar statistics of the VAE latents (population standard deviation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatentStats {
    /// Mean of all z₀ entries.
    pub shape_mean: f64,
    /// Standard deviation of all z₀ entries.
    pub shape_std: f64,
    /// Mean of all trajectory-latent entries.
    pub motion_mean: f64,
    /// Standard deviation of all trajectory-latent entries.
    pub motion_std: f64,
}

impl LatentStats {
    /// Identity statistics (mean 0, std 1): standardization does nothing.
    pub fn identity() -> Self {
        Self {
            shape_mean: 0.0,
            shape_std: 1.0,
            motion_mean: 0.0,
            motion_std: 1.0,
        }
    }

    /// (z₀ − mean) / std for shape latents of any shape.
    pub fn standardize_shape<const R: usize>(&self, z0: Tensor<R>) -> Tensor<R> {
        z0.sub_scalar(self.shape_mean).div_scalar(self.shape_std)
    }

    /// z₀ · std + mean, the inverse of [`Self::standardize_shape`].
    pub fn destandardize_shape<const R: usize>(&self, z0: Tensor<R>) -> Tensor<R> {
        z0.mul_scalar(self.shape_std).add_scalar(self.shape_mean)
    }

    /// (z − mean) / std for trajectory latents of any shape.
    pub fn standardize_motion<const R: usize>(&self, z: Tensor<R>) -> Tensor<R> {
        z.sub_scalar(self.motion_mean).div_scalar(self.motion_std)
    }

    /// z · std + mean, the inverse of [`Self::standardize_motion`].
    pub fn destandardize_motion<const R: usize>(&self, z: Tensor<R>) -> Tensor<R> {
        z.mul_scalar(self.motion_std).add_scalar(self.motion_mean)
    }
}

/// Why accumulated statistics cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LatentStatsError {
    /// No latent entries were accumulated for a stream.
    #[error("latent statistics: no {stream} latents were accumulated")]
    Empty { stream: &'static str },
    /// The standard deviation is zero or not finite, so standardization would divide by it.
    #[error("latent statistics: {stream} mean {mean} / std {std} is not usable (std must be finite and > 0)")]
    Degenerate { stream: &'static str, mean: f64, std: f64 },
}

/// Running count, mean and sum of squared deviations of one stream (Welford, merged batch-wise by Chan's rule).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Welford {
    /// Number of entries.
    pub count: u64,
    /// Running mean.
    pub mean: f64,
    /// Running sum of squared deviations from the mean.
    pub m2: f64,
}

impl Welford {
    /// Merges a batch given by its count, mean and sum of squared deviations.
    pub fn merge(&mut self, count: u64, mean: f64, m2: f64) {
        if count == 0 {
            return;
        }
        let total = self.count + count;
        let delta = mean - self.mean;
        self.mean += delta * count as f64 / total as f64;
        self.m2 += m2 + delta * delta * self.count as f64 * count as f64 / total as f64;
        self.count = total;
    }

    /// Merges every entry of a tensor (batch mean and deviations computed on its device).
    pub fn update<const R: usize>(&mut self, x: Tensor<R>) {
        let count = x.shape().num_elements() as u64;
        if count == 0 {
            return;
        }
        let mean = scalar(x.clone().mean());
        let m2 = scalar(x.sub_scalar(mean).powi_scalar(2).sum());
        self.merge(count, mean, m2);
    }

    fn finish(&self, stream: &'static str) -> Result<(f64, f64), LatentStatsError> {
        if self.count == 0 {
            return Err(LatentStatsError::Empty { stream });
        }
        let std = (self.m2 / self.count as f64).sqrt();
        if !(std.is_finite() && std > 0.0 && self.mean.is_finite()) {
            return Err(LatentStatsError::Degenerate {
                stream,
                mean: self.mean,
                std,
            });
        }
        Ok((self.mean, std))
    }
}

fn scalar(x: Tensor<1>) -> f64 {
    x.into_data().convert::<f64>().try_to_vec::<f64>().expect("f64 data")[0]
}

/// Accumulates [`LatentStats`] over batches of (posterior-sampled) latents.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LatentStatsAccumulator {
    /// Shape-latent stream.
    pub shape: Welford,
    /// Trajectory-latent stream.
    pub motion: Welford,
}

impl LatentStatsAccumulator {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one batch.
    ///
    /// # Shapes
    /// - `z0`: `[B, P, C]`, `z`: `[B, G, P, C]` (G = T frames, or 1 for the sequence-wise VAE)
    pub fn update(&mut self, z0: Tensor<3>, z: Tensor<4>) {
        self.shape.update(z0);
        self.motion.update(z);
    }

    /// The global statistics.
    ///
    /// # Errors
    /// [`LatentStatsError`] if a stream is empty or has a zero / non-finite standard deviation.
    pub fn finish(&self) -> Result<LatentStats, LatentStatsError> {
        let (shape_mean, shape_std) = self.shape.finish("shape")?;
        let (motion_mean, motion_std) = self.motion.finish("motion")?;
        Ok(LatentStats {
            shape_mean,
            shape_std,
            motion_mean,
            motion_std,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batchwise_welford_matches_two_pass_statistics() {
        let device = Device::flex();
        let a: Vec<f32> = (0..24).map(|i| (i as f32 * 0.37).sin() * 3.0 + 1.5).collect();
        let b: Vec<f32> = (0..40).map(|i| (i as f32 * 0.11).cos() - 0.5).collect();
        let mut acc = LatentStatsAccumulator::new();
        for (chunk_a, chunk_b) in [(&a[..12], &b[..20]), (&a[12..], &b[20..])] {
            let z0 = Tensor::<1>::from_floats(chunk_a, &device).reshape([1, 3, 4]);
            let z = Tensor::<1>::from_floats(chunk_b, &device).reshape([1, 5, 2, 2]);
            acc.update(z0, z);
        }
        let stats = acc.finish().expect("non-degenerate");
        let two_pass = |v: &[f32]| {
            let m = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / v.len() as f64;
            (m, var.sqrt())
        };
        let (ma, sa) = two_pass(&a);
        let (mb, sb) = two_pass(&b);
        assert!(
            (stats.shape_mean - ma).abs() < 1e-5 && (stats.shape_std - sa).abs() < 1e-5,
            "{stats:?}"
        );
        assert!(
            (stats.motion_mean - mb).abs() < 1e-5 && (stats.motion_std - sb).abs() < 1e-5,
            "{stats:?}"
        );

        let z = Tensor::<1>::from_floats(&b[..8], &device).reshape([1, 2, 2, 2]);
        let back = stats.destandardize_motion(stats.standardize_motion(z.clone()));
        let diff = (back - z).abs().max().into_data().try_to_vec::<f32>().expect("f32")[0];
        assert!(diff < 1e-5, "round trip error {diff}");
    }

    #[test]
    fn empty_or_constant_streams_are_errors() {
        let device = Device::flex();
        assert_eq!(
            LatentStatsAccumulator::new().finish(),
            Err(LatentStatsError::Empty { stream: "shape" })
        );
        let mut acc = LatentStatsAccumulator::new();
        acc.update(Tensor::ones([1, 2, 2], &device), Tensor::ones([1, 1, 2, 2], &device));
        assert!(matches!(
            acc.finish(),
            Err(LatentStatsError::Degenerate { stream: "shape", .. })
        ));
    }

    #[test]
    fn stats_round_trip_through_json() {
        let s = LatentStats {
            shape_mean: 0.25,
            shape_std: 1.5,
            motion_mean: -0.125,
            motion_std: 0.75,
        };
        let text = serde_json::to_string(&s).expect("serialize");
        assert_eq!(serde_json::from_str::<LatentStats>(&text).expect("deserialize"), s);
        assert!(serde_json::from_str::<LatentStats>(&text.replace("}", ",\"extra\":1}")).is_err());
    }
}
