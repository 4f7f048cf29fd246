//! The slot-major token layout of the keyframe RF (docs/method.md §4.1, (R3)): one token per FPS point, the T + 1
//! slots (the reference and every frame) in its channels.

use burn::prelude::*;

use super::KeyframeConditioning;

/// Keyframe replacement `m ⊙ z_key + (1 − m) ⊙ x` — the first half of (R3), and of (R7) when `z_key` is noised.
///
/// # Shapes
/// - x, z_key: `[B, P, T, C]` (token-major: the layout of the network's output)
/// - mask: `[B, T]`, 1 = observed keyframe
/// - output: `[B, P, T, C]`
pub fn replace_keyframes(x: Tensor<4>, z_key: Tensor<4>, mask: Tensor<2>) -> Tensor<4> {
    let [b, t] = mask.dims();
    let m = mask.reshape([b, 1, t, 1]);
    // (R3) Ẑ = m ⊙ Z_key + (1 − m) ⊙ X
    z_key * m.clone() + x * m.neg().add_scalar(1.0)
}

/// Interleaves the slots into the network input: slot-major `[z_s(C) ‖ m̂_s(1)]`, s = 0..T, with m̂ = [0; m]
/// (mask channels only for [`KeyframeConditioning::has_mask_channels`]). The second half of (R3).
///
/// # Shapes
/// - z0: `[B, P, C]` shape latent (slot 0)
/// - state: `[B, P, T, C]` trajectory slots 1..T (already replaced where wanted)
/// - mask: `[B, T]` mask channel values, 1 = observed
/// - output: `[B, P, (T+1)(C+1)]` or `[B, P, (T+1)·C]`
pub fn assemble_input(
    z0: Tensor<3>,
    state: Tensor<4>,
    mask: Tensor<2>,
    conditioning: KeyframeConditioning,
) -> Tensor<3> {
    let [b, p, t, c] = state.dims();
    let slots = Tensor::cat(vec![z0.unsqueeze_dim::<4>(2), state], 2); // [B, P, T+1, C]
    if !conditioning.has_mask_channels() {
        return slots.reshape([b, p, (t + 1) * c]);
    }
    let device = mask.device();
    let m_hat = Tensor::cat(vec![Tensor::<2>::zeros([b, 1], &device), mask], 1); // m̂ = [0; m]
    let m_hat = m_hat.reshape([b, 1, t + 1, 1]).expand([b, p, t + 1, 1]);
    Tensor::cat(vec![slots, m_hat], 3).reshape([b, p, (t + 1) * (c + 1)])
}

/// The network input of (R3): keyframe slots take `z_key` where `mask` = 1 (not for [`KeyframeConditioning::None`]), slot 0 takes
/// the clean shape latent, and mask channels m̂ = [0; m] follow each slot when the mode has them.
///
/// # Shapes
/// - z0: `[B, P, C]`; x, z_key: `[B, P, T, C]`; mask: `[B, T]` (1 = observed)
/// - output: `[B, P, in_channels]` with in_channels = (T+1)(C+1) or (T+1)·C
pub fn build_input(
    z0: Tensor<3>,
    x: Tensor<4>,
    mask: Tensor<2>,
    z_key: Tensor<4>,
    conditioning: KeyframeConditioning,
) -> Tensor<3> {
    let state = if conditioning.replaces_keyframes() {
        replace_keyframes(x, z_key, mask.clone())
    } else {
        x
    };
    assemble_input(z0, state, mask, conditioning)
}

/// Inverse of the output layout: slot-major velocities of slots 1..T.
///
/// # Shapes
/// - v: `[B, P, T·C]`
/// - output: `[B, P, T, C]`
pub fn split_output(v: Tensor<3>, frames: usize) -> Tensor<4> {
    let [b, p, tc] = v.dims();
    assert!(
        tc % frames == 0,
        "split_output: {tc} channels are not a multiple of {frames} frames"
    );
    v.reshape([b, p, frames, tc / frames])
}

/// Flattens `[B, P, T, C]` into the output layout `[B, P, T·C]` (inverse of [`split_output`]).
pub fn merge_slots(x: Tensor<4>) -> Tensor<3> {
    let [b, p, t, c] = x.dims();
    x.reshape([b, p, t * c])
}
