//! Text encoders of the RF (docs/method.md §4.4): one trait giving per-token states `[B, L, D_txt]` and a padding mask
//! `[B, L]`. Implementations: [`scratch`] (a small transformer trained jointly with the RF over a tokenizer trained
//! on the captions), [`clip`] (CLIP ViT-L/14 text tower, the paper's encoder, loading a user's HF safetensors),
//! [`bert`] (sentence-transformer BERT such as all-MiniLM-L6-v2). Pretrained encoders are frozen and cached.

pub mod bert;
pub mod clip;
pub mod scratch;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use burn::prelude::*;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Bool, TensorData};

/// Encoded captions.
#[derive(Clone, Debug)]
pub struct TextBatch {
    /// Per-token states, `[B, L, D]`.
    pub states: Tensor<3>,
    /// `[B, L]`, true = padding position (no caption token). An empty caption is all padding for the scratch
    /// encoder (unconditional).
    pub pad_mask: Tensor<2, Bool>,
}

/// keep_txt of each caption: 0 for a caption with no text (empty or only whitespace), 1 otherwise. A caption with
/// no text is then the same network input as the unconditional branch of classifier-free guidance (keep_txt = 0
/// zeroes the projected text before its LayerNorm, docs/method.md §4.3), in training, validation and sampling.
pub fn caption_keep(captions: &[String]) -> Vec<f32> {
    captions
        .iter()
        .map(|c| if c.trim().is_empty() { 0.0 } else { 1.0 })
        .collect()
}

/// A caption encoder.
pub trait TextEncoder {
    /// Encodes captions, padded/truncated to [`TextEncoder::max_len`] tokens.
    ///
    /// # Shapes
    /// - output: states `[B, L, D]` with B = `captions.len()`, L = `max_len()`, D = `dim()`; pad_mask `[B, L]`
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError>;
    /// Width D of the token states (the RF's `text_dim`).
    fn dim(&self) -> usize;
    /// Tokens L per caption.
    fn max_len(&self) -> usize;
}

/// Errors of tokenizers and weight loading; each names the file and the tensor or field.
#[derive(Debug, thiserror::Error)]
pub enum TextError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// The tokenizer library rejected a file or an input.
    #[error("{path}: tokenizer error: {message}")]
    Tokenizer { path: PathBuf, message: String },
    /// A tensor the model needs is absent from the weight file.
    #[error("{path}: missing tensor '{name}'")]
    MissingTensor { path: PathBuf, name: String },
    /// A tensor has another shape than the configured model expects.
    #[error("{path}: tensor '{name}' has shape {found:?}, expected {expected:?}")]
    ShapeMismatch {
        path: PathBuf,
        name: String,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    /// Any other problem with a weight or config file.
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// Token ids of a batch, padded to a fixed length.
#[derive(Clone, Debug, PartialEq)]
pub struct PaddedIds {
    /// `B · L` ids, row-major.
    pub ids: Vec<i64>,
    /// `B · L`, true = padding.
    pub pad: Vec<bool>,
    /// B.
    pub batch: usize,
    /// L.
    pub len: usize,
}

impl PaddedIds {
    /// Ids as a tensor `[B, L]`.
    pub fn ids_tensor(&self, device: &Device) -> Tensor<2, Int> {
        Tensor::from_data(TensorData::new(self.ids.clone(), [self.batch, self.len]), device)
    }

    /// Padding mask `[B, L]`, true = padding.
    pub fn pad_tensor(&self, device: &Device) -> Tensor<2, Bool> {
        Tensor::from_data(TensorData::new(self.pad.clone(), [self.batch, self.len]), device)
    }
}

/// Loads a `tokenizer.json`, with the file's own padding and truncation switched off (we pad ourselves).
pub fn load_tokenizer(path: &Path) -> Result<tokenizers::Tokenizer, TextError> {
    let mut tok = tokenizers::Tokenizer::from_file(path).map_err(|e| TextError::Tokenizer {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    tok.with_padding(None);
    tok.with_truncation(None).map_err(|e| TextError::Tokenizer {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(tok)
}

/// Tokenizes with the tokenizer's special tokens; a sequence longer than `max_len` keeps its first `max_len − 1`
/// tokens and its last one (the end token), shorter ones are padded with `pad_id`.
pub fn pad_batch(
    tok: &tokenizers::Tokenizer,
    captions: &[String],
    max_len: usize,
    pad_id: u32,
    add_special_tokens: bool,
    source: &Path,
) -> Result<PaddedIds, TextError> {
    let mut ids = Vec::with_capacity(captions.len() * max_len);
    let mut pad = Vec::with_capacity(captions.len() * max_len);
    for caption in captions {
        let enc = tok
            .encode(caption.as_str(), add_special_tokens)
            .map_err(|e| TextError::Tokenizer {
                path: source.to_path_buf(),
                message: format!("{caption:?}: {e}"),
            })?;
        let mut row: Vec<u32> = enc.get_ids().to_vec();
        if row.len() > max_len {
            let last = *row.last().expect("non-empty");
            row.truncate(max_len - 1);
            row.push(last);
        }
        let n = row.len();
        ids.extend(row.into_iter().map(i64::from));
        ids.extend(std::iter::repeat_n(i64::from(pad_id), max_len - n));
        pad.extend(std::iter::repeat_n(false, n));
        pad.extend(std::iter::repeat_n(true, max_len - n));
    }
    Ok(PaddedIds {
        ids,
        pad,
        batch: captions.len(),
        len: max_len,
    })
}

/// Multi-head scaled dot-product self-attention of the text encoders.
///
/// # Shapes
/// - q, k, v: `[B, L, D]`; pad: optional `[B, L]` (true = padding key, excluded); output `[B, L, D]`
pub(crate) fn text_self_attention(
    q: Tensor<3>,
    k: Tensor<3>,
    v: Tensor<3>,
    heads: usize,
    pad: Option<Tensor<2, Bool>>,
    causal: bool,
) -> Tensor<3> {
    let [b, l, d] = q.dims();
    let split = |x: Tensor<3>| x.reshape([b, l, heads, d / heads]).swap_dims(1, 2);
    // A large negative bias instead of −∞: a row whose keys are all padding stays finite (its output is unused).
    let bias = pad.map(|p| {
        let device = p.device();
        Tensor::<4>::zeros([b, 1, 1, l], &device)
            .mask_fill(p.reshape([b, 1, 1, l]), -1e9)
            .expand([b, heads, l, l])
    });
    let options = AttentionModuleOptions {
        scale: None,
        softcap: None,
        is_causal: causal,
    };
    let out = attention(split(q), split(k), split(v), None, bias, options);
    out.swap_dims(1, 2).reshape([b, l, d])
}

/// Host copy of one caption's encoding: states and padding mask.
type CachedCaption = (Vec<f32>, Vec<bool>);

/// A frozen encoder's outputs, cached per caption on the host (docs/method.md §4.4).
pub struct CachedEncoder<E: TextEncoder> {
    inner: E,
    cache: Mutex<HashMap<String, CachedCaption>>,
}

impl<E: TextEncoder> CachedEncoder<E> {
    /// Wraps a frozen encoder.
    pub fn new(inner: E) -> Self {
        Self {
            inner,
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// Number of cached captions.
    pub fn cached(&self) -> usize {
        self.cache.lock().map_or(0, |c| c.len())
    }
}

impl<E: TextEncoder> TextEncoder for CachedEncoder<E> {
    fn encode(&self, captions: &[String], device: &Device) -> Result<TextBatch, TextError> {
        let (l, d) = (self.inner.max_len(), self.inner.dim());
        let mut cache = self.cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let missing: Vec<String> = {
            let mut seen = std::collections::HashSet::new();
            captions
                .iter()
                .filter(|c| !cache.contains_key(*c) && seen.insert((*c).clone()))
                .cloned()
                .collect()
        };
        if !missing.is_empty() {
            let batch = self.inner.encode(&missing, device)?;
            let states: Vec<f32> =
                batch
                    .states
                    .into_data()
                    .convert::<f32>()
                    .try_into_vec()
                    .map_err(|e| TextError::Invalid {
                        path: PathBuf::from("<cache>"),
                        message: format!("{e:?}"),
                    })?;
            let pad: Vec<bool> = batch
                .pad_mask
                .into_data()
                .try_into_vec()
                .map_err(|e| TextError::Invalid {
                    path: PathBuf::from("<cache>"),
                    message: format!("{e:?}"),
                })?;
            for (i, caption) in missing.into_iter().enumerate() {
                let row = states[i * l * d..(i + 1) * l * d].to_vec();
                cache.insert(caption, (row, pad[i * l..(i + 1) * l].to_vec()));
            }
        }
        let mut states = Vec::with_capacity(captions.len() * l * d);
        let mut pad = Vec::with_capacity(captions.len() * l);
        for caption in captions {
            let (s, p) = &cache[caption];
            states.extend_from_slice(s);
            pad.extend_from_slice(p);
        }
        let b = captions.len();
        Ok(TextBatch {
            states: Tensor::from_data(TensorData::new(states, [b, l, d]), device),
            pad_mask: Tensor::from_data(TensorData::new(pad, [b, l]), device),
        })
    }

    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn max_len(&self) -> usize {
        self.inner.max_len()
    }
}

/// Loads HF safetensors into a module: PyTorch → burn layout (Linear transposed, LayerNorm weight/bias →
/// gamma/beta), with `remaps` (regex, replacement) applied to the file's names. Every tensor the module needs must
/// be present with the right shape; extra tensors in the file are ignored. Errors name the file and the tensor.
pub(crate) fn load_safetensors<M: burn::store::ModuleSnapshot>(
    module: &mut M,
    path: &Path,
    remaps: &[(&str, &str)],
) -> Result<(), TextError> {
    use burn::store::{ApplyError, PyTorchToBurnAdapter, SafetensorsStore};
    if !path.is_file() {
        return Err(TextError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "weight file not found"),
        });
    }
    let mut store = SafetensorsStore::from_file(path)
        .with_from_adapter(PyTorchToBurnAdapter)
        .allow_partial(true)
        .validate(false);
    for (from, to) in remaps {
        store = store.with_key_remapping(*from, *to);
    }
    let result = module.load_from(&mut store).map_err(|e| TextError::Invalid {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if let Some(err) = result.errors.first() {
        return Err(match err {
            ApplyError::ShapeMismatch {
                path: name,
                expected,
                found,
            } => TextError::ShapeMismatch {
                path: path.to_path_buf(),
                name: name.clone(),
                expected: expected.to_vec(),
                found: found.to_vec(),
            },
            other => TextError::Invalid {
                path: path.to_path_buf(),
                message: other.to_string(),
            },
        });
    }
    if let Some((name, _)) = result.missing.first() {
        return Err(TextError::MissingTensor {
            path: path.to_path_buf(),
            name: name.clone(),
        });
    }
    Ok(())
}
