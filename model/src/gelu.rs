//! The exact GELU, `x · Φ(x)` with Φ the standard normal CDF (docs/method.md §11), computed on the host for f32
//! tensors on a CPU backend.
//!
//! burn-flex evaluates GELU and its gradient one element at a time through a scalar `erf` (libm), which made
//! the activation about a quarter of a small RF's sampling time. Here Φ comes from a rational approximation of
//! `erf` on `[-4, 4]` (Eigen's, the one XLA and TVM use; no branch, no `exp`), evaluated over contiguous
//! slices in a loop the compiler vectorises. Its `erf` is within 3.2e-7 of the exact one after f32 rounding (tested
//! against a double-precision reference). The loops run under pulp's runtime dispatch (AVX-512 or AVX2 where the CPU
//! has them). Other backends and dtypes use burn's own `gelu`.
//!
//! With autodiff the activation is written as `x ⊙ G + C`, where `G = Φ(x) + x φ(x)` is the exact derivative
//! and `C = −x² φ(x)`; both are computed on the host as constants, so the value is `x Φ(x)` and the gradient
//! that flows to `x` is `G`, one multiplication in the backward pass instead of a second scalar `erf`.

use burn::backend::DispatchDevice;
use burn::prelude::*;
use burn::tensor::{DType, TensorData};
use rayon::prelude::*;
use std::f32::consts::FRAC_1_SQRT_2;

/// Elements per parallel chunk: below this a second thread costs more than it saves.
const CHUNK: usize = 1 << 15;

/// `1/√(2π)`.
const FRAC_1_SQRT_2PI: f32 = 0.398_942_3;

/// The exact GELU, `x · Φ(x)` (docs/method.md §11).
pub fn gelu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if !host_path(&x) {
        return burn::tensor::activation::gelu(x);
    }
    let shape = x.shape();
    let device = x.device();
    if !x.is_tracked() {
        // x is not needed after this: its buffer (not copied when x holds it alone) becomes the output.
        let mut y = match x.into_data().try_into_vec::<f32>() {
            Ok(y) => y,
            Err(e) => unreachable!("host_path admits f32 tensors only: {e}"),
        };
        y.par_chunks_mut(CHUNK)
            .for_each(|y| pulp::Arch::new().dispatch(Values(y)));
        return Tensor::from_data(TensorData::new(y, shape), (&device, DType::F32));
    }
    // x stays in the graph, so its values are copied out; that copy becomes G.
    let mut g = match x.clone().into_data().try_into_vec::<f32>() {
        Ok(g) => g,
        Err(e) => unreachable!("host_path admits f32 tensors only: {e}"),
    };
    let mut c = vec![0.0f32; g.len()];
    g.par_chunks_mut(CHUNK)
        .zip(c.par_chunks_mut(CHUNK))
        .for_each(|(g, c)| pulp::Arch::new().dispatch(SlopeOffset(g, c)));
    let g = Tensor::from_data(TensorData::new(g, shape.clone()), (&device, DType::F32));
    let c = Tensor::from_data(TensorData::new(c, shape), (&device, DType::F32));
    x * g + c
}

/// True where the host path applies: an f32 tensor on a CPU backend, with or without autodiff.
fn host_path<const D: usize>(x: &Tensor<D>) -> bool {
    let device = x.device().without_autodiff();
    x.dtype() == DType::F32
        && matches!(
            device.as_dispatch(),
            DispatchDevice::Flex(_) | DispatchDevice::NdArray(_)
        )
}

// The loops below run through pulp's dispatch: inlined into a function compiled for the widest vector
// instructions this CPU has (AVX-512 or AVX2+FMA, chosen at run time), where the binary's baseline x86-64 target
// would give them 4-lane SSE.

/// [`gelu_in_place`] under pulp's dispatch.
struct Values<'a>(&'a mut [f32]);

impl pulp::WithSimd for Values<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        gelu_in_place(self.0);
    }
}

/// [`slope_offset_in_place`] under pulp's dispatch.
struct SlopeOffset<'a>(&'a mut [f32], &'a mut [f32]);

impl pulp::WithSimd for SlopeOffset<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        slope_offset_in_place(self.0, self.1);
    }
}

/// `x ← x Φ(x)`.
#[inline(always)]
fn gelu_in_place(xs: &mut [f32]) {
    for x in xs {
        *x *= normal_cdf(*x);
    }
}

/// `g ← Φ(x) + x φ(x)` (the derivative; g holds x on entry) and `c ← −x² φ(x)`, so that `x g + c = x Φ(x)`.
#[inline(always)]
fn slope_offset_in_place(g: &mut [f32], c: &mut [f32]) {
    for (g, c) in g.iter_mut().zip(c.iter_mut()) {
        let x = *g;
        // x φ(x) is 0 in f32 beyond |x| ≈ 14; clamping keeps it 0 (not ∞ · 0) at x = ±∞.
        let xc = x.clamp(-16.0, 16.0);
        let xpdf = xc * FRAC_1_SQRT_2PI * exp_nonpositive(-0.5 * xc * xc);
        *g = normal_cdf(x) + xpdf;
        *c = -xc * xpdf;
    }
}

/// `e^y` for `y ≤ 0` in f32 without a call or a branch, so that the loops above vectorise (libm's `expf` is a
/// scalar call per element): `y = n ln 2 + r` with `|r| ≤ ln 2 / 2` (ln 2 split in two parts, so `r` is exact to
/// f32), Cephes' minimax polynomial for `e^r` (within 2 ulp), and `2^n` assembled in the exponent bits. Below −87
/// `2^n` is no longer a normal f32 and the result is 0 (the exact value is under 1.7e-38 there). NaN stays NaN.
#[inline(always)]
#[allow(clippy::excessive_precision)]
fn exp_nonpositive(y: f32) -> f32 {
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_375; // few mantissa bits: n · LN2_HI is exact
    const LN2_LO: f32 = -2.121_944_4e-4;
    const ROUND: f32 = 12_582_912.0; // 1.5 · 2^23: adding and subtracting it rounds to the nearest integer
    let yc = y.clamp(-87.0, 0.0);
    let n = (yc * LOG2_E + ROUND) - ROUND;
    let r = (yc - n * LN2_HI) - n * LN2_LO;
    let mut p = 1.987_569_150_0e-4f32;
    p = p * r + 1.398_199_950_7e-3;
    p = p * r + 8.333_451_907_3e-3;
    p = p * r + 4.166_579_589_4e-2;
    p = p * r + 1.666_666_545_9e-1;
    p = p * r + 5.000_000_120_1e-1;
    let er = p * r * r + r + 1.0;
    let scale = f32::from_bits(((n as i32 + 127) as u32) << 23);
    let e = er * scale;
    if y < -87.0 {
        0.0
    } else if y.is_nan() {
        y
    } else {
        e
    }
}

/// Φ(x) = (1 + erf(x/√2)) / 2.
#[inline(always)]
fn normal_cdf(x: f32) -> f32 {
    0.5 + 0.5 * erf(x * FRAC_1_SQRT_2)
}

/// `erf(x)` in f32: `x · α(x²) / β(x²)` on `x` clamped to `[-4, 4]` (outside it erf is ±1 in f32), with
/// Eigen's minimax coefficients. A NaN input stays NaN.
#[inline(always)]
#[allow(clippy::excessive_precision)]
fn erf(x: f32) -> f32 {
    let x = x.clamp(-4.0, 4.0);
    let x2 = x * x;
    let mut p = x2 * -2.726_142_258_013_06e-10 + 2.770_681_424_959_02e-08;
    p = x2 * p - 2.101_024_020_825_08e-06;
    p = x2 * p - 5.692_506_394_623_46e-05;
    p = x2 * p - 7.349_906_303_268_55e-04;
    p = x2 * p - 2.954_599_808_540_25e-03;
    p = x2 * p - 1.609_603_332_624_15e-02;
    let mut q = x2 * -1.456_607_184_649_96e-05 - 2.133_740_552_789_05e-04;
    q = x2 * q - 1.682_826_974_382_03e-03;
    q = x2 * q - 7.373_329_167_204_68e-03;
    q = x2 * q - 1.426_473_905_141_89e-02;
    x * p / q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// erf in f64, to ~1e-11: its Taylor series for |x| ≤ 3 (cancellation costs ~5 of 16 digits there), and
    /// 1 − erfc(|x|) from erfc's continued fraction beyond.
    fn erf_reference(x: f64) -> f64 {
        if x.abs() <= 3.0 {
            let (mut term, mut sum) = (x, x);
            for n in 1..200 {
                term *= -x * x / n as f64;
                sum += term / (2 * n + 1) as f64;
            }
            return sum * 2.0 / std::f64::consts::PI.sqrt();
        }
        let a = x.abs();
        let mut fraction = a;
        for k in (1..200).rev() {
            fraction = a + (k as f64 / 2.0) / fraction;
        }
        let erfc = (-a * a).exp() / (std::f64::consts::PI.sqrt() * fraction);
        x.signum() * (1.0 - erfc)
    }

    fn gelu_exact(x: f64) -> f64 {
        0.5 * x * (1.0 + erf_reference(x / std::f64::consts::SQRT_2))
    }

    #[test]
    fn erf_matches_a_double_precision_reference_to_4e_7() {
        let mut worst = 0.0f64;
        for i in -6000..=6000 {
            let x = i as f32 / 1000.0;
            worst = worst.max((erf(x) as f64 - erf_reference(x as f64)).abs());
        }
        assert!(worst < 4e-7, "worst |erf error| {worst:e}");
        assert_eq!(erf(f32::INFINITY), 1.0);
        assert_eq!(erf(f32::NEG_INFINITY), -1.0);
        assert!(erf(f32::NAN).is_nan());
    }

    #[test]
    fn exp_nonpositive_is_within_2_ulp_of_exp_and_zero_below_its_range() {
        let mut worst = 0.0f64;
        for i in 0..=2_000_000 {
            let y = -(i as f32) * 4.4e-5; // 0 down to −88
            let got = f64::from(exp_nonpositive(y));
            let want = f64::from(y).exp();
            if y < -87.0 {
                assert_eq!(got, 0.0, "e^{y}");
                continue;
            }
            let rel = (got - want).abs() / want;
            worst = worst.max(rel);
            assert!(rel <= 2.0 * f64::from(f32::EPSILON), "e^{y}: {got} vs {want} ({rel:e})");
        }
        assert!(worst > 0.0, "compared in f64, so f32 results differ somewhere");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(f32::NEG_INFINITY), 0.0);
        assert!(exp_nonpositive(f32::NAN).is_nan());
    }

    #[test]
    fn host_gelu_and_its_gradient_match_the_exact_function() {
        let xs: Vec<f32> = (-1000..=1000).map(|i| i as f32 / 125.0).collect();
        let (mut y, mut g, mut c) = (xs.clone(), xs.clone(), vec![0.0; xs.len()]);
        gelu_in_place(&mut y);
        slope_offset_in_place(&mut g, &mut c);
        for (i, &x) in xs.iter().enumerate() {
            let x64 = x as f64;
            let h = 1e-4;
            // A few units in the last place of x: the f32 rounding of the products, not the approximation.
            let tol = 3e-7 * x64.abs().max(1.0);
            let slope = (gelu_exact(x64 + h) - gelu_exact(x64 - h)) / (2.0 * h);
            assert!((y[i] as f64 - gelu_exact(x64)).abs() < tol, "gelu({x}) = {}", y[i]);
            assert!((g[i] as f64 - slope).abs() < 1e-5, "gelu'({x}) = {} vs {slope}", g[i]);
            let value = x * g[i] + c[i];
            assert!((value as f64 - gelu_exact(x64)).abs() < tol, "x g + c at {x} = {value}");
        }
    }

    #[test]
    fn host_gelu_matches_burn_gelu_in_value_and_gradient() {
        let device = Device::flex();
        let values: Vec<f32> = (0..(3 * CHUNK + 17))
            .map(|i| ((i * 7919) % 20001) as f32 / 1250.0 - 8.0)
            .collect();
        let n = values.len();
        let input = Tensor::<1>::from_data(TensorData::new(values.clone(), [n]), &device);
        // The largest difference in units of max(1, |x|): products round to a few ulps of x.
        let worst = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .zip(&values)
                .map(|((a, b), x)| (a - b).abs() / x.abs().max(1.0))
                .fold(0.0, f32::max)
        };
        let ours = gelu(input.clone()).into_data().try_to_vec::<f32>().unwrap();
        let burns = burn::tensor::activation::gelu(input)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert!(worst(&ours, &burns) < 3e-7, "ours − burn: {:e}", worst(&ours, &burns));

        let ad = device.clone().autodiff();
        let tracked = Tensor::<1>::from_data(TensorData::new(values.clone(), [n]), &ad).require_grad();
        assert!(
            host_path(&tracked) && host_path(&(tracked.clone() * 2.0)),
            "autodiff tensors take the host path"
        );
        assert!(host_path(&Tensor::<1>::zeros([2], &device)));
        assert!(
            !host_path(&Tensor::<1>::zeros([2], (&device, DType::F64))),
            "only f32 is computed on the host"
        );
        let grad_of = |f: &dyn Fn(Tensor<1>) -> Tensor<1>| {
            let x = Tensor::<1>::from_data(TensorData::new(values.clone(), [n]), &ad).require_grad();
            let weights = (0..n).map(|i| (i % 5) as f32 - 2.0).collect::<Vec<_>>();
            let weights = Tensor::<1>::from_data(TensorData::new(weights, [n]), &ad);
            let y = f(x.clone());
            let value = y.clone().into_data().try_to_vec::<f32>().unwrap();
            let grads = (y * weights).sum().backward();
            (value, x.grad(&grads).unwrap().into_data().try_to_vec::<f32>().unwrap())
        };
        let (v_ours, g_ours) = grad_of(&|x| gelu(x));
        let (v_burn, g_burn) = grad_of(&|x| burn::tensor::activation::gelu(x));
        let (dv, dg) = (worst(&v_ours, &v_burn), worst(&g_ours, &g_burn));
        assert!(dv < 3e-7 && dg < 1e-6, "value {dv:e}, gradient {dg:e}");
    }

    #[test]
    fn host_gelu_gradients_flow_through_intermediate_and_strided_tensors_and_not_into_constants() {
        let device = Device::flex();
        let ad = device.clone().autodiff();
        let values: Vec<f32> = (0..60).map(|i| i as f32 / 6.0 - 5.0).collect();
        // A non-leaf input, 2-D and transposed (not contiguous), against burn's gelu on the same graph.
        let grad_of = |f: &dyn Fn(Tensor<2>) -> Tensor<2>| {
            let leaf = Tensor::<1>::from_data(TensorData::new(values.clone(), [60]), &ad).require_grad();
            let x = (leaf.clone() * 2.0).reshape([6, 10]).swap_dims(0, 1);
            let y = f(x);
            let weights = Tensor::<2>::from_data(
                TensorData::new((0..60).map(|i| (i % 7) as f32 - 3.0).collect::<Vec<_>>(), [10, 6]),
                &ad,
            );
            let value = y.clone().into_data().try_to_vec::<f32>().unwrap();
            let grads = (y * weights).sum().backward();
            (
                value,
                leaf.grad(&grads).unwrap().into_data().try_to_vec::<f32>().unwrap(),
            )
        };
        let (v_ours, g_ours) = grad_of(&|x| gelu(x));
        let (v_burn, g_burn) = grad_of(&|x| burn::tensor::activation::gelu(x));
        for i in 0..60 {
            assert!(
                (v_ours[i] - v_burn[i]).abs() < 3e-6,
                "value {i}: {} vs {}",
                v_ours[i],
                v_burn[i]
            );
            assert!(
                (g_ours[i] - g_burn[i]).abs() < 1e-5,
                "gradient {i}: {} vs {}",
                g_ours[i],
                g_burn[i]
            );
        }
        // A constant on an autodiff device (no gradient asked for) is computed like any untracked tensor.
        let constant = Tensor::<1>::from_data(TensorData::new(values.clone(), [60]), &ad);
        assert!(
            !constant.is_tracked() && !gelu(constant).is_tracked(),
            "a constant input gives a constant output"
        );
    }

    #[test]
    fn host_gelu_keeps_burns_values_at_infinities_and_nan() {
        let device = Device::flex();
        let special = vec![f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 0.0];
        let plain = gelu(Tensor::<1>::from_data(TensorData::new(special.clone(), [4]), &device));
        let x = Tensor::<1>::from_data(TensorData::new(special, [4]), &device.autodiff()).require_grad();
        let tracked = gelu(x);
        for out in [plain, tracked] {
            let v = out.into_data().try_to_vec::<f32>().unwrap();
            assert_eq!(v[0], f32::INFINITY);
            assert!(
                v[1].is_nan() && v[2].is_nan(),
                "−∞ · Φ(−∞) = −∞ · 0 and NaN stay NaN, as in burn: {v:?}"
            );
            assert_eq!(v[3], 0.0);
        }
    }
}
