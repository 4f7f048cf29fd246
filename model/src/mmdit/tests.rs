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
    let scene_tokens = model.scene().tokens() as u64;
    let text_len = text_len + scene_tokens;
    for p in named_params(model).into_iter().filter(|p| p.shape.len() == 2) {
        let layer = p.path.iter().rev().nth(1).map_or("", String::as_str);
        let applications = match (p.path[0].as_str(), layer) {
            ("input_proj" | "output_proj", _) => tokens,
            ("text_proj", _) => text_len - scene_tokens,
            ("scene_global", "patch_proj") => scene_tokens,
            ("scene_global", "scene_global") if p.path.last().is_some_and(|n| n == "position") => 0, // added
            ("scene_local", _) => tokens,
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
    for (cfg, tokens, text_len) in [(MmditConfig::tiny(), 7, 3), (other, 5, 11), (scene_config(), 6, 2)] {
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

/// A network that reads both scene parts: a 6 × 2 × 6 grid in 3 × 1 × 3 = 9 patches of 2³ cells.
fn scene_config() -> MmditConfig {
    let mut cfg = MmditConfig::tiny();
    cfg.scene = SceneConditioning {
        global: true,
        local: true,
        grid: [6, 2, 6],
        cell: 0.5,
        patch: 2,
    };
    cfg
}

#[test]
fn scene_parts_count_their_parameters_and_are_absent_when_off() {
    let device = Device::flex();
    let count = |cfg: &MmditConfig| {
        named_params(&cfg.init(&device))
            .iter()
            .map(|p| p.numel())
            .sum::<usize>()
    };
    let off = MmditConfig::tiny();
    let on = scene_config();
    assert_eq!(on.scene.tokens(), 9);
    assert_eq!(count(&on) - count(&off), on.scene.param_count(on.width, on.frames));
    let mut global = on.clone();
    global.scene.local = false;
    let mut local = on.clone();
    local.scene.global = false;
    assert_eq!(
        count(&global) + count(&local) - 2 * count(&off),
        on.scene.param_count(on.width, on.frames)
    );
    assert!(
        named_params(&off.init(&device))
            .iter()
            .all(|p| !p.path[0].starts_with("scene"))
    );
}

#[test]
fn scene_layouts_that_do_not_tile_are_refused_by_key() {
    let mut cfg = scene_config();
    cfg.scene.patch = 4;
    let msg = cfg.validate().unwrap_err();
    assert!(msg.contains("model.scene.patch 4"), "{msg}");
    cfg.scene.global = false; // the patch only matters to the grid tokens
    cfg.validate().unwrap();
    cfg.scene.grid = [0, 2, 6];
    assert!(cfg.validate().unwrap_err().contains("model.scene.grid"));
    cfg.scene.grid = [6, 2, 6];
    cfg.scene.cell = f32::NAN;
    assert!(cfg.validate().unwrap_err().contains("model.scene.cell"));
    cfg.scene.local = false; // nothing read, nothing checked
    cfg.validate().unwrap();
    let mut big = scene_config();
    big.scene.grid = [64, 64, 64];
    assert!(big.validate().unwrap_err().contains("more than 65536"));
    let mut baseline = scene_config();
    baseline.conditioning = KeyframeConditioning::ReplaceNoised;
    assert!(baseline.validate().unwrap_err().contains("model.scene.local"));
    baseline.scene.local = false;
    baseline.validate().unwrap();
}

/// (S3)–(S4) at the network, with every zero-initialised layer woken: the scene changes the output only through
/// the parts that are on; offsets at frames that are not keyframes, and any offset of a clip without a scene, change
/// nothing (docs/method.md §4.12's mask polarity: m = 1 is a keyframe); `None` is the empty scene.
#[test]
fn the_scene_reaches_the_output_only_through_keyframes_and_the_grid() {
    let device = Device::flex();
    let cfg = scene_config();
    let model = cfg.init(&device).map(&mut Wake);
    let (b, p, l, t) = (2, 5, 3, cfg.frames);
    let normal = |dims: [usize; 3]| Tensor::<3>::random(dims, Distribution::Normal(0.0, 1.0), &device);
    let (input, text) = (normal([b, p, cfg.in_channels()]), normal([b, l, cfg.text_dim]));
    let (keep, tau) = (Tensor::<1>::ones([b], &device), Tensor::<1>::full([b], 0.4, &device));
    let grid = Tensor::<2>::random([b, cfg.scene.grid_cells()], Distribution::Bernoulli(0.3), &device);
    let offsets = Tensor::<4>::random([b, p, t, 3], Distribution::Normal(0.0, 1.0), &device);
    // Frame 1 is a keyframe of both clips, frame 2 of none; the second clip has no scene.
    let mask = Tensor::<2>::from_data(TensorData::new(vec![0f32, 1., 0., 1., 0., 1., 0., 0.], [b, t]), &device);
    let present = Tensor::<1>::from_data(TensorData::new(vec![1f32, 0.], [b]), &device);
    let run = |model: &Mmdit, grid: Tensor<2>, offsets: Tensor<4>| {
        let scene = SceneInput::new(grid, offsets, mask.clone(), present.clone());
        model.forward_in_scene(input.clone(), text.clone(), keep.clone(), tau.clone(), Some(&scene))
    };
    let gap = |a: Tensor<3>, b: Tensor<3>| (a - b).abs().max().into_scalar::<f32>();
    let base = run(&model, grid.clone(), offsets.clone());
    let bump = |frame: usize| {
        let mut o = offsets.clone();
        let slice = o.clone().narrow(2, frame, 1).add_scalar(0.7);
        o = o.slice_assign([0..b, 0..p, frame..frame + 1, 0..3], slice);
        o
    };
    let first = |x: Tensor<3>| x.narrow(0, 0, 1);
    let second = |x: Tensor<3>| x.narrow(0, 1, 1);
    assert!(
        gap(first(run(&model, grid.clone(), bump(1))), first(base.clone())) > 1e-3,
        "a keyframe's offset is ignored"
    );
    assert!(
        gap(run(&model, grid.clone(), bump(2)), base.clone()) < 1e-6,
        "a non-keyframe's offset is read"
    );
    assert!(
        gap(second(run(&model, grid.clone(), bump(1))), second(base.clone())) < 1e-6,
        "a clip without a scene reads offsets"
    );
    assert!(
        gap(
            run(&model, grid.clone().neg().add_scalar(1.0), offsets.clone()),
            base.clone()
        ) > 1e-3,
        "the grid is ignored"
    );
    // None is the empty scene.
    let empty = SceneInput::none(b, cfg.scene.grid_cells(), p, t, &device);
    let none = model.forward_in_scene(input.clone(), text.clone(), keep.clone(), tau.clone(), None);
    assert!(
        gap(
            none.clone(),
            model.forward_in_scene(input.clone(), text.clone(), keep.clone(), tau.clone(), Some(&empty))
        ) < 1e-6
    );
    // A network without scene parts ignores the scene.
    let plain = MmditConfig::tiny().init(&device).map(&mut Wake);
    let plain_scene = plain.forward_in_scene(
        input.clone(),
        text.clone(),
        keep.clone(),
        tau.clone(),
        Some(&SceneInput::new(grid, offsets, mask.clone(), present.clone())),
    );
    assert!(gap(plain_scene, plain.forward(input, text, keep, tau)) < 1e-6);
}

/// At initialisation the offsets' embedding is zero: a network with the local part starts as one without it.
#[test]
fn the_local_part_starts_silent() {
    let device = Device::flex();
    let mut cfg = scene_config();
    cfg.scene.global = false;
    let model = cfg.init(&device);
    let scene = SceneInput::new(
        Tensor::zeros([1, cfg.scene.grid_cells()], &device),
        Tensor::ones([1, 3, cfg.frames, 3], &device),
        Tensor::ones([1, cfg.frames], &device),
        Tensor::ones([1], &device),
    );
    let embedded = model.scene_local.as_ref().unwrap().forward(scene.keyframes);
    assert_eq!(embedded.abs().max().into_scalar::<f32>(), 0.0);
}
