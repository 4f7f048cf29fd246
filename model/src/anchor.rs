//! The keyframe-interpolation anchor of the flow (docs/method.md §4.10, `model.anchor`): the interpolation A of the
//! keyframe latents along the frames, and the maps between the flow's residual state and latents that
//! `rectified_flow` applies in training and sampling.

use burn::prelude::*;

use crate::mmdit::Anchor;

/// The keyframes' interpolation A along the frames (docs/method.md §4.10): at a keyframe its own latent, between two
/// keyframes a < f < b the line (L1) A_f = Z_a + (f − a)/(b − a)(Z_b − Z_a), before the first (after the last)
/// keyframe that keyframe's latent, and 0 in a window without keyframes. Only keyframe slots of `z_key` are read.
///
/// # Shapes
/// - z_key: `[B, P, T, C]`; mask: `[B, T]`, 1 = observed; output `[B, P, T, C]`
pub fn keyframe_lerp(z_key: Tensor<4>, mask: Tensor<2>) -> Tensor<4> {
    let [b, p, t, c] = z_key.dims();
    let device = z_key.device();
    let host: Vec<f32> = mask
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("a float tensor converts to f32 values");
    let weights = Tensor::<3>::from_data(TensorData::new(lerp_weights(&host, b, t), [b, t, t]), &device);
    let z = z_key.swap_dims(1, 2).reshape([b, t, p * c]);
    weights.matmul(z).reshape([b, t, p, c]).swap_dims(1, 2)
}

/// The rows of [`keyframe_lerp`] as a matrix per window: entry (f, g) is the weight of frame g's latent in A_f.
///
/// # Shapes
/// - mask: `B · T` row-major, > 0.5 = keyframe; output `B · T · T` row-major `[B, T, T]`
fn lerp_weights(mask: &[f32], b: usize, t: usize) -> Vec<f32> {
    let mut w = vec![0.0f32; b * t * t];
    for bi in 0..b {
        let keys: Vec<usize> = (0..t).filter(|&f| mask[bi * t + f] > 0.5).collect();
        let (Some(&first), Some(&last)) = (keys.first(), keys.last()) else {
            continue;
        };
        let row = |f: usize, g: usize| bi * t * t + f * t + g;
        for f in 0..t {
            if f <= first {
                w[row(f, first)] = 1.0;
            } else if f >= last {
                w[row(f, last)] = 1.0;
            } else {
                let i = keys.partition_point(|&k| k <= f); // keys[i − 1] ≤ f < keys[i]
                let (a, bk) = (keys[i - 1], keys[i]);
                let x = (f - a) as f32 / (bk - a) as f32;
                w[row(f, a)] += 1.0 - x;
                w[row(f, bk)] += x;
            }
        }
    }
    w
}

/// The anchor A and scale s of [`Anchor::KeyframeLerp`] for these keyframes; `None` for [`Anchor::None`].
pub(crate) fn anchor_of(anchor: Anchor, z_key: &Tensor<4>, mask: &Tensor<2>) -> Option<(Tensor<4>, f64)> {
    match anchor {
        Anchor::None => None,
        Anchor::KeyframeLerp { scale } => Some((keyframe_lerp(z_key.clone(), mask.clone()), scale)),
    }
}

/// The flow's state x as latents: A + s x with an anchor (docs/method.md §4.10), x itself without.
pub(crate) fn lift(anchor: &Option<(Tensor<4>, f64)>, x: Tensor<4>) -> Tensor<4> {
    match anchor {
        Some((a, s)) => a.clone() + x.mul_scalar(*s),
        None => x,
    }
}
