//! Keyframe-conditioned rectified-flow backbone: the MMDiT of docs/method.md §4.1 and §4.3 (CompletionAny4D P-Eq. 9 and
//! 14, on AnimateAnyMesh's "40m" CogX-style MMDiT), plus the slot-major token layout of (R3).
//!
//! Reading order as in DiT's `models.py`: helpers → timestep embedder → block (`pre_attention` / joint attention /
//! `post_attention`, as in SD3's `mmdit.py`) → model. One token per FPS point; the 16 frames live in the channels.

use crate::gelu::gelu;
use burn::nn::{LayerNorm, Linear};
use burn::prelude::*;
use burn::tensor::activation::silu;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;

mod config;
mod estimates;
mod layout;
mod scene;

pub use config::*;
pub use estimates::*;
pub use layout::*;
pub use scene::*;

/// Frequencies of the timestep sinusoid (docs/method.md §4.3): the embedding has `2 · TIME_FREQS` values `[cos ‖ sin]`.
pub const TIME_FREQS: usize = 256;
/// Epsilon of the affine-free LayerNorm in front of the joint attention (AAM `LN0`).
const PRE_NORM_EPS: f64 = 1e-6;

// ---------------------------------------------------------------------------------------------------------------
// Helpers

/// LayerNorm over the last axis without affine parameters (AAM `LN0`, eps 1e-6).
fn plain_layer_norm(x: Tensor<3>) -> Tensor<3> {
    let mean = x.clone().mean_dim(2);
    let centred = x - mean;
    let var = centred.clone().square().mean_dim(2);
    centred / var.add_scalar(PRE_NORM_EPS).sqrt()
}

/// `x · (1 + scale) + shift` with per-sample `[B, 1, W]` modulation.
fn modulate(x: Tensor<3>, shift: Tensor<3>, scale: Tensor<3>) -> Tensor<3> {
    x.clone() * scale + x + shift
}

/// Sinusoid of the raw flow time: `f_i = exp(−ln(10⁴)·i/256)`, output `[cos(τ f) ‖ sin(τ f)]` (docs/method.md §4.3).
///
/// # Shapes
/// - tau: `[B]` (τ ∈ [0, 1], τ = 0 noise, τ = 1 data)
/// - output: `[B, 2·TIME_FREQS]`
pub fn timestep_sinusoid(tau: Tensor<1>) -> Tensor<2> {
    let device = tau.device();
    let freqs = Tensor::<1, Int>::arange(0..TIME_FREQS as i64, &device)
        .float()
        .mul_scalar(-(10_000f64.ln()) / TIME_FREQS as f64)
        .exp();
    let angles = tau.unsqueeze_dim::<2>(1) * freqs.unsqueeze_dim::<2>(0);
    Tensor::cat(vec![angles.clone().cos(), angles.sin()], 1)
}

// ---------------------------------------------------------------------------------------------------------------
// Timestep embedder

/// Sinusoid of τ → Linear(512 → 4W) → GELU → Linear(4W → W) (docs/method.md §4.3; no SiLU in front).
#[derive(Module, Debug)]
pub struct TimestepEmbedder {
    fc1: Linear,
    fc2: Linear,
}

impl TimestepEmbedder {
    /// # Shapes
    /// - tau: `[B]` raw flow time (τ, not 1 − τ)
    /// - output: `[B, W]`
    pub fn forward(&self, tau: Tensor<1>) -> Tensor<2> {
        self.fc2.forward(gelu(self.fc1.forward(timestep_sinusoid(tau))))
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Block

/// The six adaLN vectors of one modality, each `[B, 1, W]`.
pub struct Modulation {
    shift_attn: Tensor<3>,
    scale_attn: Tensor<3>,
    gate_attn: Tensor<3>,
    shift_mlp: Tensor<3>,
    scale_mlp: Tensor<3>,
    gate_mlp: Tensor<3>,
}

impl Modulation {
    fn from_linear(ada: &Linear, temb_act: Tensor<2>) -> Self {
        let mut parts = ada.forward(temb_act).unsqueeze_dim::<3>(1).chunk(6, 2).into_iter();
        let mut next = || parts.next().expect("six adaLN chunks");
        Self {
            shift_attn: next(),
            scale_attn: next(),
            gate_attn: next(),
            shift_mlp: next(),
            scale_mlp: next(),
            gate_mlp: next(),
        }
    }
}

/// One MMDiT block (CogX style): per-modality adaLN, joint attention and MLP with weights shared by both streams.
#[derive(Module, Debug)]
pub struct MmditBlock {
    ada_motion: Linear,
    ada_text: Linear,
    qkv: Linear,
    proj: Linear,
    norm2_motion: LayerNorm,
    norm2_text: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
}

impl MmditBlock {
    /// adaLN of both streams and their concatenation for the joint attention.
    ///
    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, temb_act `[B, W]` (SiLU already applied)
    /// - output: joint `[B, P+L, W]` and the two modulations
    pub fn pre_attention(
        &self,
        motion: Tensor<3>,
        text: Tensor<3>,
        temb_act: Tensor<2>,
    ) -> (Tensor<3>, Modulation, Modulation) {
        let mod_m = Modulation::from_linear(&self.ada_motion, temb_act.clone());
        let mod_t = Modulation::from_linear(&self.ada_text, temb_act);
        let motion_in = modulate(
            plain_layer_norm(motion),
            mod_m.shift_attn.clone(),
            mod_m.scale_attn.clone(),
        );
        let text_in = modulate(
            plain_layer_norm(text),
            mod_t.shift_attn.clone(),
            mod_t.scale_attn.clone(),
        );
        (Tensor::cat(vec![motion_in, text_in], 1), mod_m, mod_t)
    }

    /// Joint multi-head self-attention over the P + L tokens, no mask, no positional encoding. The qkv output is
    /// head-major with `q | k | v` inside each head (AAM memory layout, so AAM weights port without permutation).
    ///
    /// # Shapes
    /// - joint: `[B, S, W]` with S = P + L; output `[B, S, W]`
    pub fn joint_attention(&self, joint: Tensor<3>) -> Tensor<3> {
        let [b, s, w] = joint.dims();
        let h = self.heads;
        let hd = w / h;
        let qkv = self.qkv.forward(joint).reshape([b, s, h, 3 * hd]).swap_dims(1, 2); // [B, H, S, 3·hd]
        let mut parts = qkv.chunk(3, 3).into_iter();
        let (q, k, v) = (parts.next().unwrap(), parts.next().unwrap(), parts.next().unwrap());
        let options = AttentionModuleOptions {
            scale: None,
            softcap: None,
            is_causal: false,
        };
        let out = attention(q, k, v, None, None, options); // [B, H, S, hd]
        self.proj.forward(out.swap_dims(1, 2).reshape([b, s, w]))
    }

    /// Gated residuals of the attention output, then adaLN + shared MLP + gated residual on each stream.
    ///
    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, attn `[B, P+L, W]`; outputs `[B, P, W]`, `[B, L, W]`
    pub fn post_attention(
        &self,
        motion: Tensor<3>,
        text: Tensor<3>,
        attn: Tensor<3>,
        mod_m: Modulation,
        mod_t: Modulation,
    ) -> (Tensor<3>, Tensor<3>) {
        let [_, p, _] = motion.dims();
        let [_, l, _] = text.dims();
        let attn_motion = attn.clone().narrow(1, 0, p);
        let attn_text = attn.narrow(1, p, l);
        let motion = motion + mod_m.gate_attn * attn_motion;
        let text = text + mod_t.gate_attn * attn_text;
        let mlp_motion = modulate(
            self.norm2_motion.forward(motion.clone()),
            mod_m.shift_mlp,
            mod_m.scale_mlp,
        );
        let mlp_text = modulate(self.norm2_text.forward(text.clone()), mod_t.shift_mlp, mod_t.scale_mlp);
        let f = self
            .fc2
            .forward(gelu(self.fc1.forward(Tensor::cat(vec![mlp_motion, mlp_text], 1))));
        let ff_motion = f.clone().narrow(1, 0, p);
        let ff_text = f.narrow(1, p, l);
        (motion + mod_m.gate_mlp * ff_motion, text + mod_t.gate_mlp * ff_text)
    }

    /// # Shapes
    /// - motion `[B, P, W]`, text `[B, L, W]`, temb_act `[B, W]`; outputs `[B, P, W]`, `[B, L, W]`
    pub fn forward(&self, motion: Tensor<3>, text: Tensor<3>, temb_act: Tensor<2>) -> (Tensor<3>, Tensor<3>) {
        let (joint, mod_m, mod_t) = self.pre_attention(motion.clone(), text.clone(), temb_act);
        let attn = self.joint_attention(joint);
        self.post_attention(motion, text, attn, mod_m, mod_t)
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Model

/// The keyframe-conditioned rectified-flow MMDiT: v_θ = MMDiT(input, text, τ) (R4).
#[derive(Module, Debug)]
pub struct Mmdit {
    input_proj: Linear,
    input_norm: LayerNorm,
    text_proj: Linear,
    text_norm: LayerNorm,
    scene_global: Option<GridEncoder>,
    scene_local: Option<KeyframeSceneEmbed>,
    time: TimestepEmbedder,
    blocks: Vec<MmditBlock>,
    final_norm: LayerNorm,
    output_proj: Linear,
    in_channels: usize,
    text_dim: usize,
    #[module(skip)]
    prediction: Prediction,
    #[module(skip)]
    anchor: Anchor,
    #[module(skip)]
    scene: SceneConditioning,
}

impl Mmdit {
    /// Velocity of slots 1..T (R4).
    ///
    /// # Shapes
    /// - input: `[B, P, in_channels]` from [`build_input`]
    /// - text: `[B, L, D_txt]` token states of the text encoder
    /// - keep_txt: `[B]`, 1 = keep the text, 0 = dropped (CFG); multiplies the projected text before its LayerNorm
    /// - tau: `[B]` flow time, 0 = noise, 1 = data
    /// - output: `[B, P, T·C]`
    ///
    /// # Panics
    /// If the channel axes do not match the config (checked with a message naming the tensor).
    pub fn forward(&self, input: Tensor<3>, text: Tensor<3>, keep_txt: Tensor<1>, tau: Tensor<1>) -> Tensor<3> {
        self.forward_in_scene(input, text, keep_txt, tau, None)
    }

    /// [`Mmdit::forward`] told about each clip's scene (docs/method.md §4.12): the grid's context tokens join the
    /// text stream after its LayerNorm (S3) and the keyframe offsets' embedding joins the motion tokens (S4), for
    /// the parts the config turns on. `None`, like a clip without a scene in training, is an empty grid and no
    /// offsets; a network without scene parts ignores the argument.
    ///
    /// # Shapes
    /// - scene: grid `[B, G]`, keyframes `[B, P, T, 4]` (see [`SceneInput`])
    pub fn forward_in_scene(
        &self,
        input: Tensor<3>,
        text: Tensor<3>,
        keep_txt: Tensor<1>,
        tau: Tensor<1>,
        scene: Option<&SceneInput>,
    ) -> Tensor<3> {
        let [b, p, in_ch] = input.dims();
        let [bt, _, d_txt] = text.dims();
        assert_eq!(
            in_ch, self.in_channels,
            "Mmdit::forward: input has {in_ch} channels, model expects {}",
            self.in_channels
        );
        assert_eq!(
            d_txt, self.text_dim,
            "Mmdit::forward: text has width {d_txt}, model expects {}",
            self.text_dim
        );
        assert_eq!(bt, b, "Mmdit::forward: text batch {bt} differs from input batch {b}");
        let device = input.device();
        let mut motion = self.input_norm.forward(self.input_proj.forward(input));
        let keep = keep_txt.reshape([b, 1, 1]);
        let mut text = self.text_norm.forward(self.text_proj.forward(text) * keep);
        if self.scene.any() {
            let none;
            let scene = match scene {
                Some(s) => s,
                None => {
                    let t = self.scene_frames();
                    none = SceneInput::none(b, self.scene.grid_cells(), p, t, &device);
                    &none
                }
            };
            if let Some(global) = &self.scene_global {
                text = Tensor::cat(vec![text, global.forward(scene.grid.clone())], 1);
            }
            if let Some(local) = &self.scene_local {
                motion = motion + local.forward(scene.keyframes.clone());
            }
        }
        let temb_act = silu(self.time.forward(tau));
        let (mut motion, mut text) = (motion, text);
        for block in &self.blocks {
            (motion, text) = block.forward(motion, text, temb_act.clone());
        }
        self.output_proj.forward(self.final_norm.forward(motion))
    }

    /// Keyframe slots T of the scene's (S4) features: the output's T·C channels over C.
    fn scene_frames(&self) -> usize {
        self.scene_local.as_ref().map_or(1, |local| local.frames())
    }

    /// Which scene features this network reads (docs/method.md §4.12).
    pub fn scene(&self) -> &SceneConditioning {
        &self.scene
    }

    /// The timestep embedder (exposed for the τ-direction test of docs/method.md §1.4).
    pub fn timestep_embedder(&self) -> &TimestepEmbedder {
        &self.time
    }

    /// Input channels this network was built for.
    pub fn in_channels(&self) -> usize {
        self.in_channels
    }

    /// Width of the text states this network reads.
    pub fn text_dim(&self) -> usize {
        self.text_dim
    }

    /// What [`Mmdit::forward`] outputs: velocities or clean latents (docs/method.md §4.9).
    pub fn prediction(&self) -> Prediction {
        self.prediction
    }

    /// What the flow generates: latents or their residual from the keyframe interpolation (docs/method.md §4.10).
    pub fn anchor(&self) -> Anchor {
        self.anchor
    }
}

#[cfg(test)]
mod tests;
