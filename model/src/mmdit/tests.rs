//! The MMDiT: estimates against the built network, parameter counts, layout and conditioning checks.

use super::*;
use crate::summary::named_params;

#[test]
fn activation_estimate_grows_with_batch_width_and_tokens() {
    let cfg = MmditConfig {
        width: 128,
        blocks: 4,
        heads: 4,
        ..MmditConfig::paper(KeyframeConditioning::InputMask, 128)
    };
    let one = cfg.activation_bytes(1, 128, 16);
    // 4 blocks × (16·128·144 + 2·4·144²) f32 values.
    assert_eq!(one, 4 * 4 * (16 * 128 * 144 + 2 * 4 * 144 * 144));
    assert_eq!(cfg.activation_bytes(32, 128, 16), 32 * one);
    assert!(cfg.activation_bytes(1, 512, 16) > 4 * one);
}

/// 2 × Σ (weight-matrix size × the number of times the layer is applied per sample), read from the module's
/// own 2-D parameters: motion-only layers act on P tokens, the text projection on L, the shared block
/// layers on S = P + L, the timestep MLP and adaLN once per sample. An unknown 2-D parameter fails the test,
/// so a Linear added to the network without updating [`MmditConfig::forward_flops`] is caught.
fn linear_flops_of_weights(model: &Mmdit, tokens: u64, text_len: u64) -> u64 {
    let mut flops = 0;
    for p in named_params(model).into_iter().filter(|p| p.shape.len() == 2) {
        let layer = p.path.iter().rev().nth(1).map_or("", String::as_str);
        let applications = match (p.path[0].as_str(), layer) {
            ("input_proj" | "output_proj", _) => tokens,
            ("text_proj", _) => text_len,
            ("time", _) | ("blocks", "ada_motion" | "ada_text") => 1,
            ("blocks", "qkv" | "proj" | "fc1" | "fc2") => tokens + text_len,
            _ => panic!("2-D parameter {} has no FLOP rule", p.path.join(".")),
        };
        flops += 2 * p.numel() as u64 * applications;
    }
    flops
}

#[test]
fn linear_flops_match_the_weights_of_the_initialised_module() {
    let device = Device::flex();
    let mut other = MmditConfig::tiny();
    (other.conditioning, other.text_dim, other.blocks, other.width) = (KeyframeConditioning::None, 12, 3, 24);
    for (cfg, tokens, text_len) in [(MmditConfig::tiny(), 7, 3), (other, 5, 11)] {
        let weights = linear_flops_of_weights(&cfg.init(&device), tokens, text_len);
        let counted = cfg.forward_flops(tokens as usize, text_len as usize);
        assert_eq!(counted.linear, weights, "{cfg:?}");
    }
}

#[test]
fn attention_flops_are_quadratic_in_the_joint_sequence_and_training_is_three_passes() {
    // Tiny: W 32, 2 blocks, S = 5 + 3 = 8: 2 blocks × (QKᵀ: 2·8·8·32 + softmax·V: 2·8·8·32) = 16384, whatever
    // the head count.
    let cfg = MmditConfig::tiny();
    let flops = cfg.forward_flops(5, 3);
    assert_eq!(flops.attention, 16_384);
    let mut more_heads = cfg.clone();
    more_heads.heads = 8;
    assert_eq!(more_heads.forward_flops(5, 3), flops);
    assert_eq!(cfg.forward_flops(13, 3).attention, 16_384 * 4);
    assert_eq!(flops.training_step(), 3 * (flops.linear + flops.attention));
}

use burn::tensor::Distribution;

/// Replaces all-zero float parameters (zero-initialised adaLN and output projections) with N(0, 0.3²), so the
/// output depends on τ.
struct Wake;

impl burn::module::ModuleMapper for Wake {
    fn map_float<const D: usize>(&mut self, param: burn::module::Param<Tensor<D>>) -> burn::module::Param<Tensor<D>> {
        param.map(|t| {
            let peak = t.clone().abs().max().into_scalar::<f32>();
            if peak == 0.0 {
                t.random_like(Distribution::Normal(0.0, 0.3))
            } else {
                t
            }
        })
    }
}

/// docs/method.md §1.4 (4) at the network: `forward(…, τ)` embeds τ itself. The reference below runs the same
/// layers with the embedding of τ written out; a flip to 1 − τ anywhere inside `forward` makes the two differ
/// (the output is checked to depend on τ, so the comparison can fail).
#[test]
fn forward_embeds_tau_not_one_minus_tau() {
    let device = Device::flex();
    let cfg = MmditConfig::tiny();
    let model = cfg.init(&device).map(&mut Wake);
    let (b, p, l) = (2, 5, 3);
    let input = Tensor::<3>::random([b, p, cfg.in_channels()], Distribution::Normal(0.0, 1.0), &device);
    let text = Tensor::<3>::random([b, l, cfg.text_dim], Distribution::Normal(0.0, 1.0), &device);
    let keep = Tensor::<1>::ones([b], &device);
    let reference = |tau: f32| {
        let tau = Tensor::<1>::full([b], tau, &device);
        let motion = model.input_norm.forward(model.input_proj.forward(input.clone()));
        let text = model.text_norm.forward(model.text_proj.forward(text.clone()));
        let temb = silu(
            model
                .time
                .fc2
                .forward(gelu(model.time.fc1.forward(timestep_sinusoid(tau)))),
        );
        let (mut m, mut t) = (motion, text);
        for block in &model.blocks {
            (m, t) = block.forward(m, t, temb.clone());
        }
        model.output_proj.forward(model.final_norm.forward(m))
    };
    let run = |tau: f32| {
        model.forward(
            input.clone(),
            text.clone(),
            keep.clone(),
            Tensor::full([b], tau, &device),
        )
    };
    let gap = |a: Tensor<3>, b: Tensor<3>| (a - b).abs().max().into_scalar::<f32>();
    for tau in [0.1f32, 0.3, 0.8] {
        assert!(
            gap(run(tau), reference(tau)) < 1e-5,
            "forward(τ = {tau}) is not the network at τ"
        );
        assert!(
            gap(reference(tau), reference(1.0 - tau)) > 1e-3,
            "the output does not depend on τ, so the check above could not fail"
        );
    }
}
