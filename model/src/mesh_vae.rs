//! The mesh VAE body both VAEs share (docs/method.md §3.1–§3.3, equations (V1)–(V3)): AnimateAnyMesh's
//! shape-synchronised attention blocks, the bottleneck, the query decoder, the losses and the [`MeshVae`]
//! interface; the frame-wise VAE (`frame_vae.rs`) and the sequence-wise DyMeshVAE (`dymesh_vae.rs`) differ only in
//! their motion embedding and output head.

use crate::gelu::gelu;
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;
use burn::tensor::module::linear;
use serde::{Deserialize, Serialize};

pub use crate::attention::EdgeList;
use crate::attention::{
    NeighbourAttention, NeighbourAttentionConfig, OutInit, SharedMapAttention, SharedMapAttentionConfig,
};
use crate::point_embed::{PointEmbed, PointEmbedConfig};

/// Whether padded vertex rows are visible as attention keys in the encoder (docs/method.md §2.4, §9 item 15).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PadKeys {
    /// Padded rows are masked out of the encoder's keys (ours, default): latents do not depend on padding.
    Masked,
    /// Padded rows are attended to, as in the AnimateAnyMesh code (reproduces its padding dependence).
    Visible,
}

/// How (V1) averages the per-vertex distances over a batch (docs/method.md (V1)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecAverage {
    /// Mean over each clip's real vertices and frames, then mean over the clips of the batch (the paper's form,
    /// default): every clip weighs the same whatever its vertex count.
    #[default]
    PerClip,
    /// One mean over all real vertices of all clips of the batch (the AnimateAnyMesh code): clips with more
    /// vertices weigh more.
    Batch,
}

/// Whether the trajectory latent is drawn from the posterior or taken as its mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Posterior {
    /// z = μ + σ·ξ with ξ ~ N(0, I) from the device RNG (training, latent statistics).
    Sample,
    /// z = μ (keyframe latents at inference, docs/method.md §4.6).
    Mean,
}

/// GEGLU feed-forward network: Linear(d → 2·m·d) → x·gelu(gate) → Linear(m·d → d), exact GELU.
#[derive(Module, Debug)]
pub struct GegluFfn {
    proj_in: Linear,
    proj_out: Linear,
}

impl GegluFfn {
    fn new(d: usize, mult: usize, device: &Device) -> Self {
        Self {
            proj_in: LinearConfig::new(d, 2 * mult * d).init(device),
            proj_out: LinearConfig::new(mult * d, d).init(device),
        }
    }

    /// # Shapes
    /// - `x`: `[.., D]` → `[.., D]`
    pub fn forward<const R: usize>(&self, x: Tensor<R>) -> Tensor<R> {
        // Same as chunking proj_in's output into (value, gate), but the split is taken on the small weight:
        // slicing the [.., 2·m·d] activation would cost two full-size zero-filled gradients in the backward.
        let hidden = self.proj_out.weight.dims()[0];
        let weight = self.proj_in.weight.val();
        let bias = self.proj_in.bias.as_ref().map(|b| b.val());
        let half = |start: usize| {
            linear(
                x.clone(),
                weight.clone().narrow(1, start, hidden),
                bias.clone().map(|b| b.narrow(0, start, hidden)),
            )
        };
        let (value, gate) = (half(0), half(hidden));
        self.proj_out.forward(value * gelu(gate))
    }
}

/// One shape-synchronised block (docs/method.md §3.2 encoder/decoder rows): one attention map computed from the shape
/// stream (queries) and the shape context (keys) pools both the shape context (updates S) and the motion
/// context (updates M); pre-LayerNorm, residuals, a GEGLU FFN per stream. The encoder uses it as
/// cross-attention into the per-vertex features, the decoder as self-attention over the P tokens.
#[derive(Module, Debug)]
pub struct SyncBlock {
    norm_q: LayerNorm,
    norm_k: LayerNorm,
    norm_v_shape: LayerNorm,
    norm_v_motion: LayerNorm,
    attn: SharedMapAttention,
    norm_ff_shape: LayerNorm,
    ff_shape: GegluFfn,
    norm_ff_motion: LayerNorm,
    ff_motion: GegluFfn,
}

impl SyncBlock {
    fn new(d: usize, heads: usize, head_dim: usize, ffn_mult: usize, device: &Device) -> Self {
        let ln = || LayerNormConfig::new(d).init(device);
        Self {
            norm_q: ln(),
            norm_k: ln(),
            norm_v_shape: ln(),
            norm_v_motion: ln(),
            attn: SharedMapAttentionConfig::new(d, d, vec![d, d], vec![d, d], heads, head_dim).init(device),
            norm_ff_shape: ln(),
            ff_shape: GegluFfn::new(d, ffn_mult, device),
            norm_ff_motion: ln(),
            ff_motion: GegluFfn::new(d, ffn_mult, device),
        }
    }

    /// # Shapes
    /// - `s`: `[B, P, D]` shape tokens, `m`: `[B, G, P, D]` motion tokens (G groups, e.g. T frames)
    /// - `ctx_shape`: `[B, Lk, D]`, `ctx_motion`: `[B, G, Lk, D]`, `key_mask`: `[B, Lk]` (true = real)
    /// - returns the updated `(s, m)`
    pub fn forward(
        &self,
        s: Tensor<3>,
        m: Tensor<4>,
        ctx_shape: Tensor<3>,
        ctx_motion: Tensor<4>,
        key_mask: Option<Tensor<2, Bool>>,
    ) -> (Tensor<3>, Tensor<4>) {
        let values = vec![
            self.norm_v_shape.forward(ctx_shape.clone()).unsqueeze_dim(1),
            self.norm_v_motion.forward(ctx_motion),
        ];
        let mut pooled = self
            .attn
            .forward(
                self.norm_q.forward(s.clone()),
                self.norm_k.forward(ctx_shape),
                values,
                key_mask,
            )
            .into_iter();
        let (ds, dm) = (
            pooled.next().expect("shape stream"),
            pooled.next().expect("motion stream"),
        );
        let s = s + ds.squeeze_dim(1);
        let m = m + dm;
        let s = s.clone() + self.ff_shape.forward(self.norm_ff_shape.forward(s));
        let m = m.clone() + self.ff_motion.forward(self.norm_ff_motion.forward(m));
        (s, m)
    }
}

/// Sizes of the encoder/decoder body both mesh VAEs share: the `[model.body]` table of `configs/vae/*.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshVaeBodyConfig {
    /// Width d (P-Table S4: 128 frame-wise; 256 sequence-wise).
    pub width: usize,
    /// Decoder self-attention heads (8).
    pub heads: usize,
    /// Decoder head width (64, AAM).
    pub head_dim: usize,
    /// Encoder cross-attention blocks (8); the encoder attention is one head of width d.
    pub enc_blocks: usize,
    /// Decoder self-attention blocks (8).
    pub dec_blocks: usize,
    /// Latent channels C per stream (12 frame-wise, 32 sequence-wise): z₀ and each trajectory latent.
    pub latent_channels: usize,
    /// Point-embedding frequencies 2^k·π (8 → 51 Fourier values).
    pub point_freqs: usize,
    /// GEGLU multiple m: d → 2m·d, gate → m·d → d (4).
    pub ffn_mult: usize,
    /// Padded vertices as encoder keys (docs/method.md §9 item 15): masked (ours) or visible (AAM).
    pub pad_keys: PadKeys,
    /// Lower clamp of log σ² (−30).
    pub logvar_min: f64,
    /// Upper clamp of log σ² (20).
    pub logvar_max: f64,
    /// How the reconstruction loss (V1) averages over a batch (`per_clip` when absent).
    #[serde(default)]
    pub rec_average: RecAverage,
}

impl MeshVaeBodyConfig {
    /// The paper's body at width `width` with `latent_channels` channels (docs/method.md §3.5).
    pub fn paper(width: usize, latent_channels: usize) -> Self {
        Self {
            width,
            heads: 8,
            head_dim: 64,
            enc_blocks: 8,
            dec_blocks: 8,
            latent_channels,
            point_freqs: 8,
            ffn_mult: 4,
            pad_keys: PadKeys::Masked,
            logvar_min: -30.0,
            logvar_max: 20.0,
            rec_average: RecAverage::PerClip,
        }
    }

    /// A small body for unit tests (d 32, 2 + 2 blocks, 2 heads of 16, C = 4).
    pub fn tiny() -> Self {
        Self {
            heads: 2,
            head_dim: 16,
            enc_blocks: 2,
            dec_blocks: 2,
            ..Self::paper(32, 4)
        }
    }

    /// Checks the sizes; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        for (name, value) in [
            ("width", self.width),
            ("heads", self.heads),
            ("head_dim", self.head_dim),
            ("latent_channels", self.latent_channels),
            ("point_freqs", self.point_freqs),
            ("ffn_mult", self.ffn_mult),
        ] {
            if value == 0 {
                return Err(format!("model.body.{name} must be positive, got 0"));
            }
        }
        if self.logvar_min.is_nan() || self.logvar_max.is_nan() || self.logvar_min >= self.logvar_max {
            return Err(format!(
                "model.body.logvar_min ({}) must be below logvar_max ({})",
                self.logvar_min, self.logvar_max
            ));
        }
        crate::summary::check_param_estimate("model.body sizes", self.param_estimate())
    }

    /// An upper estimate of the body's parameter count, computed without allocating: every block's attention
    /// (4·d·max(d, heads·head_dim)) and GEGLU feed-forward (3m·d²), the query decoder (≈ 12 d²) and the embeddings.
    pub fn param_estimate(&self) -> u128 {
        let d = self.width as u128;
        let inner = (self.heads as u128 * self.head_dim as u128).max(d);
        let blocks = self.enc_blocks as u128 + self.dec_blocks as u128;
        let per_block = 4 * d * inner + 3 * self.ffn_mult as u128 * d * d + 4 * d;
        let embed = (6 * self.point_freqs as u128 + 3) * d + 6 * self.latent_channels as u128 * d;
        blocks * per_block + 12 * d * d + embed
    }

    /// A rough count of the bytes one training micro-batch keeps for the backward pass (f32), computed without
    /// allocating, for `groups` motion groups (frames), N = `vertices` (the padded count) and P = `tokens`: per
    /// stream (shape + groups) and encoder block the P × N cross-attention map twice, keys and values of every
    /// vertex and about (8 + 3m)·d values per token; per decoder block the tokens and two `heads × P × P` maps; the
    /// vertex embeddings and the query decoding (a P-wide map per vertex, 2d-wide queries and outputs per group).
    pub fn activation_bytes(&self, micro_batch: usize, groups: usize, vertices: usize, tokens: usize) -> u128 {
        let (b, g, n, p) = (micro_batch as u128, groups as u128, vertices as u128, tokens as u128);
        let (d, heads, m) = (self.width as u128, self.heads as u128, self.ffn_mult as u128);
        let streams = g + 1;
        let token_values = (8 + 3 * m) * p * d;
        let encoder = self.enc_blocks as u128 * streams * (2 * p * n + 2 * n * d + token_values);
        let decoder = self.dec_blocks as u128 * streams * (token_values + 2 * heads * p * p);
        let vertices_values = 20 * n * d + 4 * g * n * d + 2 * n * p + 4 * g * n * d;
        4 * b * (encoder + decoder + vertices_values)
    }

    /// Builds the body on `device`; each vertex decodes `out_per_group` values per motion group (3 per frame, or
    /// 3T for a whole-clip trajectory).
    pub fn init(&self, out_per_group: usize, device: &Device) -> MeshVaeBody {
        let (d, c) = (self.width, self.latent_channels);
        let lin = |a: usize, b: usize| LinearConfig::new(a, b).init(device);
        MeshVaeBody {
            point_embed: PointEmbedConfig::new(d).with_point_freqs(self.point_freqs).init(device),
            neighbour: NeighbourAttentionConfig::new(d, 2 * d).init(device),
            // Encoder: one head of width d (AAM).
            encoder: (0..self.enc_blocks)
                .map(|_| SyncBlock::new(d, 1, d, self.ffn_mult, device))
                .collect(),
            z0_head: lin(d, c),
            mu_head: lin(d, c),
            logvar_head: lin(d, c),
            z0_in: lin(c, d),
            z_in: lin(c, d),
            decoder: (0..self.dec_blocks)
                .map(|_| SyncBlock::new(d, self.heads, self.head_dim, self.ffn_mult, device))
                .collect(),
            query_proj: lin(d, 2 * d),
            query_norm: LayerNormConfig::new(2 * d).init(device),
            token_norm_k: LayerNormConfig::new(d).init(device),
            token_norm_v: LayerNormConfig::new(d).init(device),
            // Query decoding: one head of width 2d, keys = shape tokens, values = motion tokens, zero-init out.
            query_attn: SharedMapAttentionConfig::new(2 * d, d, vec![d], vec![2 * d], 1, 2 * d)
                .with_out_init(OutInit::Zeros)
                .init(device),
            to_offsets: lin(2 * d, out_per_group),
            pad_keys: self.pad_keys,
            rec_average: self.rec_average,
            logvar_range: (self.logvar_min, self.logvar_max),
        }
    }
}

/// Encoder/decoder body of both mesh VAEs, generic only in the number of motion groups G (T frames, or 1
/// whole-clip trajectory) and in the latent and output sizes. The motion-input embedding lives in the VAE.
#[derive(Module, Debug)]
pub struct MeshVaeBody {
    point_embed: PointEmbed,
    neighbour: NeighbourAttention,
    encoder: Vec<SyncBlock>,
    z0_head: Linear,
    mu_head: Linear,
    logvar_head: Linear,
    z0_in: Linear,
    z_in: Linear,
    decoder: Vec<SyncBlock>,
    query_proj: Linear,
    query_norm: LayerNorm,
    token_norm_k: LayerNorm,
    token_norm_v: LayerNorm,
    query_attn: SharedMapAttention,
    to_offsets: Linear,
    #[module(skip)]
    pad_keys: PadKeys,
    #[module(skip)]
    rec_average: RecAverage,
    #[module(skip)]
    logvar_range: (f64, f64),
}

/// Gathers the FPS rows of per-vertex features.
///
/// # Shapes
/// - `x`: `[B, G, N, D]`, `fps`: `[B, P]` → `[B, G, P, D]`
pub fn gather_tokens(x: Tensor<4>, fps: Tensor<2, Int>) -> Tensor<4> {
    let [b, g, n, d] = x.dims();
    let p = fps.dims()[1];
    // Whole rows of the flattened [B·G·N, D] features (row (b·G + g)·N + fps[b, p]): a row select, whose
    // backward is one row scatter, instead of an element-wise gather over a [B, G, P, D] index.
    let base = Tensor::<1, Int>::arange(0..(b * g) as i64, &fps.device()).mul_scalar(n as i64);
    let rows = base.reshape([b, g, 1]) + fps.reshape([b, 1, p]);
    x.reshape([b * g * n, d])
        .select(0, rows.reshape([b * g * p]))
        .reshape([b, g, p, d])
}

impl MeshVaeBody {
    /// Per-vertex shape features E₀ of the reference mesh: point embedding, then neighbour attention.
    ///
    /// # Shapes
    /// - `reference`: `[B, N, 3]` → `[B, N, D]`
    pub fn encode_shape(&self, reference: Tensor<3>, edges: &EdgeList) -> Tensor<3> {
        self.neighbour.forward(self.point_embed.forward(reference), edges)
    }

    /// Encoder blocks and bottleneck: returns `(z₀, μ, log σ²)`.
    ///
    /// # Shapes
    /// - `e0`: `[B, N, D]`, `motion`: `[B, G, N, D]` embedded motion input of every vertex
    /// - `vmask`: `[B, N]` (true = real vertex), `fps`: `[B, P]`
    /// - returns `z₀` `[B, P, C]`, `μ` and `log σ²` `[B, G, P, C]`
    pub fn encode_tokens(
        &self,
        e0: Tensor<3>,
        motion: Tensor<4>,
        vmask: Tensor<2, Bool>,
        fps: Tensor<2, Int>,
    ) -> (Tensor<3>, Tensor<4>, Tensor<4>) {
        let key_mask = match self.pad_keys {
            PadKeys::Masked => Some(vmask),
            PadKeys::Visible => None,
        };
        let mut s: Tensor<3> = gather_tokens(e0.clone().unsqueeze_dim(1), fps.clone()).squeeze_dim(1);
        let mut m = gather_tokens(motion.clone(), fps);
        for block in &self.encoder {
            (s, m) = block.forward(s, m, e0.clone(), motion.clone(), key_mask.clone());
        }
        let z0 = self.z0_head.forward(s);
        let mu = self.mu_head.forward(m.clone());
        let logvar = self
            .logvar_head
            .forward(m)
            .clamp(self.logvar_range.0, self.logvar_range.1);
        (z0, mu, logvar)
    }

    /// Decoder blocks and query decoding: per-vertex outputs for every motion group.
    ///
    /// # Shapes
    /// - `e0`: `[B, N, D]`, `z0`: `[B, P, C]`, `z`: `[B, G, P, C]`
    /// - returns `[B, G, N, out_per_group]` (offsets from the reference)
    pub fn decode_offsets(&self, e0: Tensor<3>, z0: Tensor<3>, z: Tensor<4>) -> Tensor<4> {
        let mut s = self.z0_in.forward(z0);
        let mut m = self.z_in.forward(z);
        for block in &self.decoder {
            (s, m) = block.forward(s.clone(), m.clone(), s, m, None);
        }
        let q = self.query_norm.forward(self.query_proj.forward(e0));
        let k = self.token_norm_k.forward(s);
        let v = self.token_norm_v.forward(m);
        // to_offsets(query_attn(q, k, v)), with the value, output and offset projections multiplied first.
        self.query_attn.forward_then(q, k, v, None, &self.to_offsets)
    }
}

/// Draws z = μ + σ·ξ, σ = exp(½ log σ²), ξ from the device RNG (docs/method.md §3.2 "Bottleneck").
///
/// # Shapes
/// - `mu`, `logvar`: `[B, G, P, C]` → `[B, G, P, C]`
pub fn sample(mu: Tensor<4>, logvar: Tensor<4>) -> Tensor<4> {
    let noise = mu.random_like(Distribution::Normal(0.0, 1.0));
    mu + logvar.mul_scalar(0.5).exp() * noise
}

/// [`sample`] with ξ drawn on the host from `rng` ([`crate::noise`]): the same draws on every backend and thread.
///
/// # Shapes
/// - `mu`, `logvar`: `[B, G, P, C]` → `[B, G, P, C]`
pub fn sample_with(mu: Tensor<4>, logvar: Tensor<4>, rng: &mut impl any4d_data::rng::Rng) -> Tensor<4> {
    let noise = crate::noise::normal(mu.dims(), rng, &mu.device());
    mu + logvar.mul_scalar(0.5).exp() * noise
}

/// (V1) mean per-vertex Euclidean distance over the real vertices of all frames: per clip
/// (1/B) Σ_b Σ_{f,v real} ‖x̂ − x̄‖₂ / (T · N_v^b), or over the whole batch Σ_{b,f,v real} ‖x̂ − x̄‖₂ / (T · Σ_b N_v)
/// (the AnimateAnyMesh code), as `average` says.
///
/// # Shapes
/// - `pred`, `target`: `[B, T, N, 3]`, `vmask`: `[B, N]` (true = real) → `[1]`
pub fn reconstruction_loss(
    pred: Tensor<4>,
    target: Tensor<4>,
    vmask: Tensor<2, Bool>,
    average: RecAverage,
) -> Tensor<1> {
    let [b, t, n, _] = pred.dims();
    let padded = vmask.clone().bool_not().reshape([b, 1, n]).expand([b, t, n]);
    let sq: Tensor<3> = (pred - target).powi_scalar(2).sum_dim(3).squeeze_dim(3);
    // Padded rows are replaced before the square root, so neither their value nor a zero distance
    // (∂√x at 0) can reach the gradient; clamp_min keeps real rows with zero error finite.
    let dist = sq
        .mask_fill(padded.clone(), 1.0)
        .clamp_min(1e-20)
        .sqrt()
        .mask_fill(padded, 0.0);
    match average {
        RecAverage::Batch => {
            let real = vmask.int().sum().float().mul_scalar(t as f64);
            dist.sum() / real
        }
        RecAverage::PerClip => {
            let per_clip: Tensor<1> = dist.sum_dim(2).sum_dim(1).reshape([b]); // [B]
            let real: Tensor<1> = vmask.int().sum_dim(1).float().reshape([b]).mul_scalar(t as f64);
            (per_clip / real).mean()
        }
    }
}

/// (V2) KL divergence of N(μ, σ²) from N(0, I): mean over every element (tokens, channels, groups, batch)
/// of ½(μ² + σ² − 1 − log σ²).
///
/// # Shapes
/// - `mu`, `logvar`: `[B, G, P, C]` → `[1]`
pub fn kl_loss(mu: Tensor<4>, logvar: Tensor<4>) -> Tensor<1> {
    (mu.powi_scalar(2) + logvar.clone().exp() - logvar)
        .sub_scalar(1.0)
        .mul_scalar(0.5)
        .mean()
}

/// Loss terms of a VAE step.
#[derive(Debug, Clone)]
pub struct VaeLoss {
    /// (V3) rec + kl_weight · kl, `[1]`.
    pub total: Tensor<1>,
    /// (V1) mean per-vertex distance, `[1]`.
    pub rec: Tensor<1>,
    /// (V2) KL term, `[1]`.
    pub kl: Tensor<1>,
}

impl VaeLoss {
    /// (V3) L = L_rec + β · L_KL.
    pub fn new(rec: Tensor<1>, kl: Tensor<1>, kl_weight: f64) -> Self {
        let total = rec.clone() + kl.clone().mul_scalar(kl_weight);
        Self { total, rec, kl }
    }
}

/// Encoder outputs of one batch.
#[derive(Debug, Clone)]
pub struct VaeEncoding {
    /// Per-vertex shape features E₀, `[B, N, D]`.
    pub e0: Tensor<3>,
    /// Deterministic shape latent z₀, `[B, P, C]`.
    pub z0: Tensor<3>,
    /// Posterior mean of the trajectory latents, `[B, G, P, C]` (G = T frame-wise, 1 sequence-wise).
    pub mu: Tensor<4>,
    /// Posterior log-variance (clamped), `[B, G, P, C]`.
    pub logvar: Tensor<4>,
}

/// One training batch of either mesh VAE, in the normalized, padded frame of docs/method.md §2.3–§2.4.
#[derive(Debug, Clone)]
pub struct VaeBatch {
    /// Reference mesh x̄₀ (clip frame 0), `[B, N, 3]`.
    pub reference: Tensor<3>,
    /// All frames x̄_f, `[B, T, N, 3]`.
    pub frames: Tensor<4>,
    /// Real-vertex mask, `[B, N]`, true = real.
    pub vmask: Tensor<2, Bool>,
    /// FPS token indices into the vertex axis, `[B, P]`.
    pub fps: Tensor<2, Int>,
    /// Mesh edges of the batch.
    pub edges: EdgeList,
    /// Seed of the posterior noise ξ, drawn on the host ([`sample_with`]); `None` draws it from the device's stream.
    pub noise_seed: Option<u64>,
}

/// The interface both mesh VAEs share (frame-wise [`crate::frame_vae::FrameVae`], sequence-wise
/// [`crate::dymesh_vae::DyMeshVae`], and [`crate::any_vae::AnyMeshVae`] holding either): each supplies its body, its
/// motion embedding, how its output head lays out offsets, and its KL weight β; encoding, decoding, the posterior
/// sample, reconstruction and the (V1)–(V3) loss are written once here. G is the latent group axis: T frame-wise,
/// 1 sequence-wise.
pub trait MeshVae {
    /// The encoder's motion input from the offsets r_f = x̄_f − x̄₀ of every frame (frame 0 included).
    ///
    /// # Shapes
    /// - `offsets`: `[B, T, N, 3]` → `[B, G, N, D]`
    fn embed_motion(&self, offsets: Tensor<4>) -> Tensor<4>;

    /// The per-frame offsets o_f from the body's decoded values.
    ///
    /// # Shapes
    /// - `decoded`: `[B, G, N, out_per_group]` → `[B, T, N, 3]`
    fn frame_offsets(&self, decoded: Tensor<4>) -> Tensor<4>;

    /// β of (V3).
    fn kl_weight(&self) -> f64;

    /// The encoder/decoder body both VAEs share.
    fn body(&self) -> &MeshVaeBody;

    /// Encodes the clip against the reference mesh: shape features E₀, then the encoder blocks over the FPS tokens.
    ///
    /// # Shapes
    /// - `reference`: `[B, N, 3]`, `frames`: `[B, T, N, 3]`, `vmask`: `[B, N]`, `fps`: `[B, P]`
    /// - returns `e0` `[B, N, D]`, `z0` `[B, P, C]`, `mu`/`logvar` `[B, G, P, C]`
    fn encode(
        &self,
        reference: Tensor<3>,
        frames: Tensor<4>,
        vmask: Tensor<2, Bool>,
        fps: Tensor<2, Int>,
        edges: &EdgeList,
    ) -> VaeEncoding {
        let e0 = self.encode_shape(reference.clone(), edges);
        let motion = self.embed_motion(frames - reference.unsqueeze_dim(1));
        let (z0, mu, logvar) = self.body().encode_tokens(e0.clone(), motion, vmask, fps);
        VaeEncoding { e0, z0, mu, logvar }
    }

    /// Decodes every frame: x̂_{f,v} = x̄_{0,v} + o_{f,v} (docs/method.md §3.2 "Output"). Padded rows get values too;
    /// the loss and metrics ignore them.
    ///
    /// # Shapes
    /// - `e0`: `[B, N, D]`, `reference`: `[B, N, 3]`, `z0`: `[B, P, C]`, `z`: `[B, G, P, C]`
    /// - returns `[B, T, N, 3]`
    fn decode(&self, e0: Tensor<3>, reference: Tensor<3>, z0: Tensor<3>, z: Tensor<4>) -> Tensor<4> {
        let offsets = self.frame_offsets(self.body().decode_offsets(e0, z0, z));
        reference.unsqueeze_dim(1) + offsets
    }

    /// Per-vertex shape features E₀ (point embedding + neighbour attention).
    ///
    /// # Shapes
    /// - `reference`: `[B, N, 3]` → `[B, N, D]`
    fn encode_shape(&self, reference: Tensor<3>, edges: &EdgeList) -> Tensor<3> {
        self.body().encode_shape(reference, edges)
    }

    /// Reparameterised sample z = μ + σ·ξ.
    ///
    /// # Shapes
    /// - `mu`, `logvar`: `[B, G, P, C]` → `[B, G, P, C]`
    fn sample(&self, mu: Tensor<4>, logvar: Tensor<4>) -> Tensor<4> {
        sample(mu, logvar)
    }

    /// [`Self::encode`] of a whole batch.
    ///
    /// # Shapes
    /// - returns `e0` `[B, N, D]`, `z0` `[B, P, C]`, `mu`/`logvar` `[B, G, P, C]`
    fn encode_vae_batch(&self, batch: &VaeBatch) -> VaeEncoding {
        self.encode(
            batch.reference.clone(),
            batch.frames.clone(),
            batch.vmask.clone(),
            batch.fps.clone(),
            &batch.edges,
        )
    }

    /// Encodes and decodes a batch; returns the reconstruction and the encoding.
    ///
    /// # Shapes
    /// - returns `[B, T, N, 3]` and the [`Self::encode`] outputs
    fn reconstruct(&self, batch: &VaeBatch, posterior: Posterior) -> (Tensor<4>, VaeEncoding) {
        let enc = self.encode_vae_batch(batch);
        let z = match posterior {
            Posterior::Sample => match batch.noise_seed {
                Some(seed) => sample_with(enc.mu.clone(), enc.logvar.clone(), &mut crate::noise::generator(seed)),
                None => self.sample(enc.mu.clone(), enc.logvar.clone()),
            },
            Posterior::Mean => enc.mu.clone(),
        };
        let recon = self.decode(enc.e0.clone(), batch.reference.clone(), enc.z0.clone(), z);
        (recon, enc)
    }

    /// Training loss (V1)–(V3) with a posterior sample.
    ///
    /// # Shapes
    /// - every term `[1]`
    fn loss(&self, batch: &VaeBatch) -> VaeLoss {
        let (recon, enc) = self.reconstruct(batch, Posterior::Sample);
        let average = self.body().rec_average;
        let rec = reconstruction_loss(recon, batch.frames.clone(), batch.vmask.clone(), average); // (V1)
        let kl = kl_loss(enc.mu, enc.logvar); // (V2)
        VaeLoss::new(rec, kl, self.kl_weight()) // (V3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gather_tokens_picks_the_fps_rows_of_every_group() {
        let device = Device::flex();
        // x[b, g, v, c] = 1000·b + 100·g + 10·v + c.
        let (b, g, n, d) = (2usize, 3usize, 5usize, 2usize);
        let x: Vec<f32> = (0..b * g * n * d)
            .map(|i| {
                let (bi, gi, vi, ci) = (i / (g * n * d), i / (n * d) % g, i / d % n, i % d);
                (1000 * bi + 100 * gi + 10 * vi + ci) as f32
            })
            .collect();
        let x = Tensor::<4>::from_data(TensorData::new(x, [b, g, n, d]), &device);
        let fps = Tensor::<2, Int>::from_data(TensorData::new(vec![4i64, 0, 2, 3], [2, 2]), &device);
        let got = gather_tokens(x, fps).into_data().try_to_vec::<f32>().expect("f32 data");
        let mut want = Vec::new();
        for (bi, picks) in [[4usize, 0], [2, 3]].iter().enumerate() {
            for gi in 0..g {
                for &vi in picks {
                    want.extend((0..d).map(|ci| (1000 * bi + 100 * gi + 10 * vi + ci) as f32));
                }
            }
        }
        assert_eq!(got, want);
    }
}
