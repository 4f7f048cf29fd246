//! Training noise drawn on the host from a seeded generator (ChaCha8), then moved to the device.
//!
//! burn's CPU backends keep one random stream per process behind a lock: two training workers on one CPU that drew
//! from it would interleave their draws in whatever order the threads reach it. Each micro-batch instead draws its
//! posterior noise ξ, flow noise ε and flow times τ from its own generator (seeded from the run's generator), so a
//! run gives the same numbers on one worker or several, on any backend, and resumes exactly.

use any4d_data::rng::{DataRng, Rng, SeedableRng};
use burn::prelude::{Device, Tensor, TensorData};

/// Box–Muller: two independent N(0, 1) draws (cosine and sine branch) from two uniforms of `rng`.
fn normal_pair(rng: &mut impl Rng) -> (f64, f64) {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]: ln is finite
    let u2: f64 = rng.random();
    let (r, angle) = ((-2.0 * u1.ln()).sqrt(), std::f64::consts::TAU * u2);
    (r * angle.cos(), r * angle.sin())
}

/// One N(0, 1) draw (the cosine branch of [`normal_pair`]).
pub fn standard_normal(rng: &mut impl Rng) -> f64 {
    normal_pair(rng).0
}

/// A tensor of independent N(0, 1) draws from `rng` ([`normal_pair`]: two values per pair of uniforms).
pub fn normal<const D: usize>(shape: [usize; D], rng: &mut impl Rng, device: &Device) -> Tensor<D> {
    let n: usize = shape.iter().product();
    let mut values = Vec::with_capacity(n + 1);
    while values.len() < n {
        let (a, b) = normal_pair(rng);
        values.push(a as f32);
        values.push(b as f32);
    }
    values.truncate(n);
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// `[n]` uniform draws in the open interval (0, 1) from `rng`.
pub fn uniform_open(n: usize, rng: &mut impl Rng, device: &Device) -> Tensor<1> {
    let values: Vec<f32> = (0..n)
        .map(|_| {
            loop {
                let u = rng.random::<f32>();
                if u > 0.0 {
                    break u;
                }
            }
        })
        .collect();
    Tensor::from_data(TensorData::new(values, [n]), device)
}

/// A generator for one use of a seed (e.g. the posterior noise of one micro-batch).
pub fn generator(seed: u64) -> DataRng {
    DataRng::seed_from_u64(seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_repeat_for_a_seed_and_have_unit_moments() {
        let device = Device::default();
        let a: Vec<f32> = normal([64, 1000], &mut generator(3), &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let b: Vec<f32> = normal([64, 1000], &mut generator(3), &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let c: Vec<f32> = normal([64, 1000], &mut generator(4), &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert_eq!(a, b, "same seed, same draws");
        assert_ne!(a, c, "another seed, other draws");
        let n = a.len() as f64;
        let mean = a.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
        let var = a.iter().map(|&x| (f64::from(x) - mean).powi(2)).sum::<f64>() / n;
        assert!(
            mean.abs() < 0.02 && (var - 1.0).abs() < 0.03,
            "mean {mean}, variance {var}"
        );
        // An odd count keeps its length (the last pair is cut).
        assert_eq!(normal([3], &mut generator(1), &device).dims(), [3]);
        let u: Vec<f32> = uniform_open(10_000, &mut generator(5), &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert!(u.iter().all(|&x| x > 0.0 && x < 1.0));
        let mean_u = u.iter().map(|&x| f64::from(x)).sum::<f64>() / u.len() as f64;
        assert!((mean_u - 0.5).abs() < 0.02, "{mean_u}");
    }
}
