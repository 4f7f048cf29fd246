//! The `scratch` text encoder (docs/method.md §4.4): a word-level tokenizer trained on the dataset's captions with the
//! `tokenizers` crate (saved as `tokenizer.json` in the run folder; its word-level trainer orders equal counts
//! alphabetically, so training is deterministic — the WordPiece trainer is not) and a small pre-LN transformer
//! trained jointly with the rectified flow. An empty caption has no tokens: all padding, zero states (unconditional).

use std::path::{Path, PathBuf};

use crate::gelu::gelu;
use burn::module::Param;
use burn::nn::{Embedding, EmbeddingConfig, Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Bool;
use serde::{Deserialize, Serialize};
use tokenizers::models::TrainerWrapper;
use tokenizers::models::wordlevel::{WordLevel, WordLevelTrainer};
use tokenizers::normalizers::BertNormalizer;
use tokenizers::pre_tokenizers::bert::BertPreTokenizer;
use tokenizers::{AddedToken, Tokenizer};

use crate::mmdit::FlopCount;

use super::{PaddedIds, TextBatch, TextEncoder, TextError, load_tokenizer, pad_batch, text_self_attention};

/// File name of the trained tokenizer inside its folder.
pub const TOKENIZER_FILE: &str = "tokenizer.json";
/// Padding token (id 0).
pub const PAD: &str = "[PAD]";
/// Unknown-word token (id 1).
pub const UNK: &str = "[UNK]";

/// Word-level tokenizer trained on captions.
pub struct ScratchTokenizer {
    tokenizer: Tokenizer,
    pad_id: u32,
    source: PathBuf,
}

impl ScratchTokenizer {
    /// Trains a lower-casing word-level tokenizer (deterministic for the same captions) on the captions (vocabulary at
    /// most `vocab_size`, special tokens
    /// `[PAD]` = 0 and `[UNK]` = 1).
    pub fn train(captions: &[String], vocab_size: usize) -> Result<Self, TextError> {
        let source = PathBuf::from("<captions>");
        let err = |e: tokenizers::Error| TextError::Tokenizer {
            path: source.clone(),
            message: e.to_string(),
        };
        let mut tokenizer = Tokenizer::new(WordLevel::builder().unk_token(UNK.to_string()).build().map_err(err)?);
        tokenizer
            .with_normalizer(Some(BertNormalizer::default()))
            .map_err(err)?;
        tokenizer.with_pre_tokenizer(Some(BertPreTokenizer));
        let trainer = WordLevelTrainer::builder()
            .vocab_size(vocab_size)
            .min_frequency(1)
            .show_progress(false)
            .special_tokens(vec![AddedToken::from(PAD, true), AddedToken::from(UNK, true)])
            .build()
            .map_err(|e| TextError::Tokenizer {
                path: source.clone(),
                message: e.to_string(),
            })?;
        let mut trainer = TrainerWrapper::WordLevelTrainer(trainer);
        tokenizer.train(&mut trainer, captions.iter()).map_err(err)?;
        Self::from_tokenizer(tokenizer, source)
    }

    fn from_tokenizer(tokenizer: Tokenizer, source: PathBuf) -> Result<Self, TextError> {
        let pad_id = tokenizer.token_to_id(PAD).ok_or_else(|| TextError::Tokenizer {
            path: source.clone(),
            message: format!("no {PAD} token in the vocabulary"),
        })?;
        Ok(Self {
            tokenizer,
            pad_id,
            source,
        })
    }

    /// Writes `dir/tokenizer.json`.
    pub fn save(&self, dir: &Path) -> Result<(), TextError> {
        let path = dir.join(TOKENIZER_FILE);
        self.tokenizer.save(&path, false).map_err(|e| TextError::Tokenizer {
            path: path.clone(),
            message: e.to_string(),
        })
    }

    /// Reads `dir/tokenizer.json`.
    pub fn load(dir: &Path) -> Result<Self, TextError> {
        let path = dir.join(TOKENIZER_FILE);
        Self::from_tokenizer(load_tokenizer(&path)?, path)
    }

    /// Vocabulary size including the special tokens.
    pub fn vocab_size(&self) -> usize {
        self.tokenizer.get_vocab_size(true)
    }

    /// Token ids padded to `max_len` (no start/end tokens).
    pub fn pad_batch(&self, captions: &[String], max_len: usize) -> Result<PaddedIds, TextError> {
        pad_batch(&self.tokenizer, captions, max_len, self.pad_id, false, &self.source)
    }
}

/// Size of the scratch text transformer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScratchTextConfig {
    /// Vocabulary size (from the trained tokenizer).
    pub vocab_size: usize,
    /// Width D of the token states.
    pub width: usize,
    /// Transformer layers.
    pub layers: usize,
    /// Attention heads.
    pub heads: usize,
    /// Tokens L per caption.
    pub max_len: usize,
}

impl ScratchTextConfig {
    /// Model FLOPs of one forward pass for one caption of `max_len` tokens, counted as in
    /// [`crate::mmdit::MmditConfig::forward_flops`]: per layer 2·L·(3W² + W² + 4W² + 4W²) for qkv, out, fc1,
    /// fc2, and 2·2·L²·W for the attention; the embedding lookups are not counted.
    pub fn forward_flops(&self) -> FlopCount {
        let [layers, l, w] = [self.layers, self.max_len, self.width].map(|x| x as u64);
        FlopCount {
            linear: layers * 2 * l * (3 * w * w + w * w + 4 * w * w + 4 * w * w),
            attention: layers * 2 * 2 * l * l * w,
        }
    }

    /// Builds the module (token and learned position embeddings N(0, 0.02²), pre-LN layers).
    pub fn init(&self, device: &Device) -> ScratchTextModel {
        let emb_init = Initializer::Normal { mean: 0.0, std: 0.02 };
        let w = self.width;
        ScratchTextModel {
            token_embedding: EmbeddingConfig::new(self.vocab_size, w)
                .with_initializer(emb_init.clone())
                .init(device),
            position_embedding: emb_init.init([self.max_len, w], device),
            layers: (0..self.layers)
                .map(|_| ScratchLayer {
                    norm1: LayerNormConfig::new(w).init(device),
                    qkv: LinearConfig::new(w, 3 * w).init(device),
                    out: LinearConfig::new(w, w).init(device),
                    norm2: LayerNormConfig::new(w).init(device),
                    fc1: LinearConfig::new(w, 4 * w).init(device),
                    fc2: LinearConfig::new(4 * w, w).init(device),
                    heads: self.heads,
                })
                .collect(),
            final_norm: LayerNormConfig::new(w).init(device),
            max_len: self.max_len,
        }
    }
}

/// One pre-LN transformer layer with padding-masked bidirectional attention.
#[derive(Module, Debug)]
pub struct ScratchLayer {
    norm1: LayerNorm,
    qkv: Linear,
    out: Linear,
    norm2: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
}

impl ScratchLayer {
    fn forward(&self, x: Tensor<3>, pad: Tensor<2, Bool>) -> Tensor<3> {
        let qkv = self.qkv.forward(self.norm1.forward(x.clone())).chunk(3, 2);
        let [q, k, v]: [Tensor<3>; 3] = qkv.try_into().expect("three chunks");
        let x = x + self
            .out
            .forward(text_self_attention(q, k, v, self.heads, Some(pad), false));
        x.clone() + self.fc2.forward(gelu(self.fc1.forward(self.norm2.forward(x))))
    }
}

/// The jointly trained caption transformer.
#[derive(Module, Debug)]
pub struct ScratchTextModel {
    token_embedding: Embedding,
    position_embedding: Param<Tensor<2>>,
    layers: Vec<ScratchLayer>,
    final_norm: LayerNorm,
    max_len: usize,
}

impl ScratchTextModel {
    /// Token states; padded positions are zero.
    ///
    /// # Shapes
    /// - ids: `[B, L]`; pad: `[B, L]` (true = padding); output `[B, L, D]`
    pub fn forward(&self, ids: Tensor<2, Int>, pad: Tensor<2, Bool>) -> Tensor<3> {
        let [b, l] = ids.dims();
        let [_, d] = self.position_embedding.lazy_shape().dims::<2>();
        let pos = self.position_embedding.val().narrow(0, 0, l).unsqueeze_dim::<3>(0);
        let mut x = self.token_embedding.forward(ids) + pos;
        for layer in &self.layers {
            x = layer.forward(x, pad.clone());
        }
        let keep = pad.bool_not().float().reshape([b, l, 1]).expand([b, l, d]);
        self.final_norm.forward(x) * keep
    }
}

/// Tokenizer + transformer as a [`TextEncoder`]. Not cached: its weights change during training.
pub struct ScratchTextEncoder {
    /// The trained tokenizer.
    pub tokenizer: ScratchTokenizer,
    /// The transformer (part of the trained RF parameters).
    pub model: ScratchTextModel,
}

impl TextEncoder for ScratchTextEncoder {
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError> {
        let ids = self.tokenizer.pad_batch(captions, self.max_len())?;
        let pad_mask = ids.pad_tensor(device);
        let states = self.model.forward(ids.ids_tensor(device), pad_mask.clone());
        Ok(TextBatch { states, pad_mask })
    }

    fn dim(&self) -> usize {
        self.model.position_embedding.lazy_shape().dims::<2>()[1]
    }

    fn max_len(&self) -> usize {
        self.model.max_len
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::named_params;

    #[test]
    fn linear_flops_match_the_weights_of_the_initialised_encoder() {
        let cfg = ScratchTextConfig {
            vocab_size: 11,
            width: 16,
            layers: 3,
            heads: 4,
            max_len: 7,
        };
        // 2 × Σ (2-D weight size × L) over the layers' Linear weights; embeddings are lookups, not products.
        let mut weights = 0u64;
        for p in named_params(&cfg.init(&Device::flex())) {
            match (p.shape.len(), p.path[0].as_str()) {
                (2, "layers") => weights += 2 * p.numel() as u64 * 7,
                (2, "token_embedding" | "position_embedding") | (1, _) => {}
                _ => panic!("parameter {} has no FLOP rule", p.path.join(".")),
            }
        }
        let flops = cfg.forward_flops();
        assert_eq!(flops.linear, weights);
        // 3 layers × (QKᵀ 2·7·7·16 + softmax·V 2·7·7·16).
        assert_eq!(flops.attention, 3 * 4 * 49 * 16);
    }
}
