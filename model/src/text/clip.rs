//! The `clip_l14` text encoder (docs/method.md §4.3–§4.4): the CLIP ViT-L/14 text transformer (causal attention,
//! quick-GELU, pre-LN, final LayerNorm; 12 layers, width 768, 77 tokens) loading a Hugging Face
//! `model.safetensors` (names `text_model.…` as in `CLIPTextModel`) and its `tokenizer.json`. Output: the
//! last-layer per-token states (not the pooled vector), padding tokens included as in the AAM code.

use std::path::{Path, PathBuf};

use burn::nn::{Embedding, EmbeddingConfig, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::activation::sigmoid;
use serde::{Deserialize, Serialize};

use super::{TextBatch, TextEncoder, TextError, load_safetensors, load_tokenizer, pad_batch, text_self_attention};

/// End-of-text token of the CLIP BPE vocabulary; also the padding token (SD 1.5 tokenizer).
pub const END_OF_TEXT: &str = "<|endoftext|>";

/// Size of the CLIP text tower (HF `CLIPTextConfig` fields).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipTextConfig {
    /// Vocabulary size (49408).
    pub vocab_size: usize,
    /// Width D (768).
    pub width: usize,
    /// Transformer layers (12).
    pub layers: usize,
    /// Attention heads (12).
    pub heads: usize,
    /// MLP hidden width (3072).
    pub intermediate: usize,
    /// Tokens L (77).
    pub max_len: usize,
    /// LayerNorm epsilon (1e-5).
    pub layer_norm_eps: f64,
}

impl ClipTextConfig {
    /// CLIP ViT-L/14 (the SD 1.5 text encoder, 123,060,480 parameters).
    pub fn vit_l14() -> Self {
        Self {
            vocab_size: 49408,
            width: 768,
            layers: 12,
            heads: 12,
            intermediate: 3072,
            max_len: 77,
            layer_norm_eps: 1e-5,
        }
    }

    /// Builds an uninitialised-weights module (random); load weights with [`ClipTextEncoder::load`].
    pub fn init(&self, device: &Device) -> ClipTextModel {
        let w = self.width;
        let ln = || LayerNormConfig::new(w).with_epsilon(self.layer_norm_eps).init(device);
        let layers = (0..self.layers)
            .map(|_| ClipEncoderLayer {
                self_attn: ClipAttention {
                    q_proj: LinearConfig::new(w, w).init(device),
                    k_proj: LinearConfig::new(w, w).init(device),
                    v_proj: LinearConfig::new(w, w).init(device),
                    out_proj: LinearConfig::new(w, w).init(device),
                    heads: self.heads,
                },
                layer_norm1: ln(),
                mlp: ClipMlp {
                    fc1: LinearConfig::new(w, self.intermediate).init(device),
                    fc2: LinearConfig::new(self.intermediate, w).init(device),
                },
                layer_norm2: ln(),
            })
            .collect();
        ClipTextModel {
            text_model: ClipTextTransformer {
                embeddings: ClipEmbeddings {
                    token_embedding: EmbeddingConfig::new(self.vocab_size, w).init(device),
                    position_embedding: EmbeddingConfig::new(self.max_len, w).init(device),
                },
                encoder: ClipEncoder { layers },
                final_layer_norm: ln(),
            },
        }
    }
}

/// `text_model.embeddings`.
#[derive(Module, Debug)]
pub struct ClipEmbeddings {
    token_embedding: Embedding,
    position_embedding: Embedding,
}

/// `…self_attn`: separate q/k/v/out projections with bias.
#[derive(Module, Debug)]
pub struct ClipAttention {
    q_proj: Linear,
    k_proj: Linear,
    v_proj: Linear,
    out_proj: Linear,
    heads: usize,
}

/// `…mlp`: fc1 → quick-GELU → fc2.
#[derive(Module, Debug)]
pub struct ClipMlp {
    fc1: Linear,
    fc2: Linear,
}

/// `text_model.encoder.layers.{i}`.
#[derive(Module, Debug)]
pub struct ClipEncoderLayer {
    self_attn: ClipAttention,
    layer_norm1: LayerNorm,
    mlp: ClipMlp,
    layer_norm2: LayerNorm,
}

/// `text_model.encoder`.
#[derive(Module, Debug)]
pub struct ClipEncoder {
    layers: Vec<ClipEncoderLayer>,
}

/// `text_model`.
#[derive(Module, Debug)]
pub struct ClipTextTransformer {
    embeddings: ClipEmbeddings,
    encoder: ClipEncoder,
    final_layer_norm: LayerNorm,
}

/// The CLIP text tower; its module paths equal the HF safetensors names.
#[derive(Module, Debug)]
pub struct ClipTextModel {
    text_model: ClipTextTransformer,
}

/// quick-GELU: x · σ(1.702 x).
fn quick_gelu(x: Tensor<3>) -> Tensor<3> {
    x.clone() * sigmoid(x.mul_scalar(1.702))
}

impl ClipEncoderLayer {
    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let h = self.layer_norm1.forward(x.clone());
        let a = &self.self_attn;
        let attn = text_self_attention(
            a.q_proj.forward(h.clone()),
            a.k_proj.forward(h.clone()),
            a.v_proj.forward(h),
            a.heads,
            None,
            true,
        );
        let x = x + a.out_proj.forward(attn);
        let h = self.layer_norm2.forward(x.clone());
        x + self.mlp.fc2.forward(quick_gelu(self.mlp.fc1.forward(h)))
    }
}

impl ClipTextModel {
    /// Last hidden state after the final LayerNorm (causal mask only, as HF `CLIPTextModel` without a mask).
    ///
    /// # Shapes
    /// - ids: `[B, L]`; output `[B, L, D]`
    pub fn forward(&self, ids: Tensor<2, Int>) -> Tensor<3> {
        let [_, l] = ids.dims();
        let device = ids.device();
        let tm = &self.text_model;
        let pos = Tensor::<1, Int>::arange(0..l as i64, &device).unsqueeze_dim::<2>(0);
        let mut x = tm.embeddings.token_embedding.forward(ids) + tm.embeddings.position_embedding.forward(pos);
        for layer in &tm.encoder.layers {
            x = layer.forward(x);
        }
        tm.final_layer_norm.forward(x)
    }
}

/// Frozen CLIP text encoder: tokenizer + weights. Wrap in [`super::CachedEncoder`] to cache per caption.
pub struct ClipTextEncoder {
    tokenizer: tokenizers::Tokenizer,
    tokenizer_path: PathBuf,
    pad_id: u32,
    config: ClipTextConfig,
    model: ClipTextModel,
}

impl ClipTextEncoder {
    /// Loads `weights` (HF `model.safetensors` of `CLIPTextModel` or `CLIPModel`; other towers are ignored) and
    /// `tokenizer` (HF `tokenizer.json`). Missing or misshaped tensors give an error naming the tensor.
    pub fn load(config: ClipTextConfig, weights: &Path, tokenizer: &Path, device: &Device) -> Result<Self, TextError> {
        let tok = load_tokenizer(tokenizer)?;
        let pad_id = tok.token_to_id(END_OF_TEXT).ok_or_else(|| TextError::Tokenizer {
            path: tokenizer.to_path_buf(),
            message: format!("no {END_OF_TEXT} token (CLIP pads with it)"),
        })?;
        let mut model = config.init(device);
        load_safetensors(&mut model, weights, &[])?;
        Ok(Self {
            tokenizer: tok,
            tokenizer_path: tokenizer.to_path_buf(),
            pad_id,
            config,
            model: model.no_grad(),
        })
    }

    /// The loaded network.
    pub fn model(&self) -> &ClipTextModel {
        &self.model
    }
}

impl TextEncoder for ClipTextEncoder {
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError> {
        let ids = pad_batch(
            &self.tokenizer,
            captions,
            self.config.max_len,
            self.pad_id,
            true,
            &self.tokenizer_path,
        )?;
        let states = self.model.forward(ids.ids_tensor(device)).detach();
        Ok(TextBatch {
            states,
            pad_mask: ids.pad_tensor(device),
        })
    }

    fn dim(&self) -> usize {
        self.config.width
    }

    fn max_len(&self) -> usize {
        self.config.max_len
    }
}
