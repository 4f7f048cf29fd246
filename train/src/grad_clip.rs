//! The global gradient-norm clip of every training loop (PyTorch's `clip_grad_norm_`; docs/method.md §3.5/§4.7
//! "gradient clip 1.0").

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::Tensor;

/// Scales `grads` so that their global L2 norm over `model`'s parameters is at most `max_norm` (PyTorch's
/// `clip_grad_norm_`, docs/method.md §3.5/§4.7 "gradient clip 1.0"); returns the clipped gradients and the norm before.
pub fn clip_global_norm<M: Module>(model: &M, mut grads: GradientsParams, max_norm: f64) -> (GradientsParams, f64) {
    struct SquaredNorm<'a> {
        grads: &'a GradientsParams,
        sum: Option<Tensor<1>>,
    }
    impl ModuleVisitor for SquaredNorm<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(g) = self.grads.get::<D>(param.id) {
                // Squared and summed in f32 (a no-op cast on f32 runs): in f16 the squares overflow at 65,504,
                // and a bf16 sum keeps 8 bits of mantissa.
                let s = g.cast(burn::tensor::FloatDType::F32).square().sum();
                self.sum = Some(match self.sum.take() {
                    Some(acc) => acc + s,
                    None => s,
                });
            }
        }
    }
    struct Scale<'a> {
        grads: &'a mut GradientsParams,
        factor: f64,
    }
    impl ModuleVisitor for Scale<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(g) = self.grads.remove::<D>(param.id) {
                self.grads.register::<D>(param.id, g.mul_scalar(self.factor));
            }
        }
    }
    let mut norm = SquaredNorm {
        grads: &grads,
        sum: None,
    };
    model.visit(&mut norm);
    let total = norm.sum.map_or(0.0, |s| f64::from(s.into_scalar::<f32>()).sqrt());
    if total > max_norm {
        let mut scale = Scale {
            grads: &mut grads,
            factor: max_norm / (total + 1e-6),
        };
        model.visit(&mut scale);
    }
    (grads, total)
}

#[cfg(test)]
mod tests {
    use burn::prelude::Device;
    use burn::tensor::{FloatDType, TensorData};

    use super::*;

    #[derive(Module, Debug)]
    struct Weights {
        w: Param<Tensor<1>>,
    }

    /// The gradients of `sum(w · c)` (each `c`) for an `n`-vector `w`, stored in `dtype`.
    fn gradients(c: f32, n: usize, dtype: FloatDType) -> (Weights, GradientsParams) {
        let device = Device::flex().autodiff();
        let tensor = |v: f32| {
            Tensor::<1>::from_data(
                TensorData::new(vec![v; n], [n]),
                (&device, burn::tensor::DType::from(dtype)),
            )
        };
        let model = Weights {
            w: Param::from_tensor(tensor(1.0)),
        };
        let loss = (model.w.val() * tensor(c)).sum();
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        (model, grads)
    }

    fn values(grads: &GradientsParams, model: &Weights) -> Vec<f32> {
        let g: Tensor<1> = grads.get(model.w.id).expect("a gradient for w");
        g.into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 values")
    }

    #[test]
    fn the_global_norm_is_the_l2_norm_and_clipping_scales_to_the_limit() {
        let (model, grads) = gradients(3.0, 4, FloatDType::F32);
        let (kept, norm) = clip_global_norm(&model, grads, 100.0);
        assert!((norm - 6.0).abs() < 1e-9, "{norm}"); // √(4 · 3²)
        assert_eq!(values(&kept, &model), vec![3.0; 4], "under the limit: unchanged");
        let (model, grads) = gradients(3.0, 4, FloatDType::F32);
        let (clipped, _) = clip_global_norm(&model, grads, 1.0);
        for v in values(&clipped, &model) {
            assert!((v - 0.5).abs() < 1e-6, "{v}"); // 3 · 1/6
        }
    }

    /// Half-precision gradients whose squares exceed f16's largest value (65,504) still give a finite norm.
    #[test]
    fn the_norm_of_half_precision_gradients_is_summed_in_f32() {
        let (model, grads) = gradients(300.0, 8, FloatDType::F16);
        assert_eq!(grads.get::<1>(model.w.id).unwrap().dtype(), FloatDType::F16.into());
        let (clipped, norm) = clip_global_norm(&model, grads, 1.0);
        let want = (8.0f64 * 300.0 * 300.0).sqrt();
        assert!((norm - want).abs() < 1e-3 * want, "{norm} vs {want}");
        for v in values(&clipped, &model) {
            assert!((f64::from(v) - 300.0 / want).abs() < 1e-3, "{v}");
        }
    }
}
