//! The trained network of an RF run: the MMDiT and, jointly, the scratch caption encoder (docs/method.md §4.3–§4.4).

use any4d_model::mmdit::{Mmdit, MmditConfig};
use any4d_model::text::scratch::{ScratchTextConfig, ScratchTextModel, ScratchTokenizer};
use burn::module::Module;
use burn::prelude::{Device, Tensor};

use crate::error::Result;

/// Sizes of [`RfModel`].
#[derive(Clone, Debug, PartialEq)]
pub struct RfModelConfig {
    /// The MMDiT.
    pub mmdit: MmditConfig,
    /// The scratch caption transformer (width = `mmdit.text_dim`).
    pub text: ScratchTextConfig,
}

impl RfModelConfig {
    /// Builds both networks on `device`.
    pub fn init(&self, device: &Device) -> RfModel {
        RfModel {
            mmdit: self.mmdit.init(device),
            text: self.text.init(device),
        }
    }
}

/// What the RF run trains: the MMDiT v_θ (R4) and, jointly, the scratch caption encoder (docs/method.md §4.4).
#[derive(Module, Debug)]
pub struct RfModel {
    /// The keyframe-conditioned velocity network.
    pub mmdit: Mmdit,
    /// The caption transformer feeding the MMDiT's text stream.
    pub text: ScratchTextModel,
}

impl RfModel {
    /// Token states of `captions` (empty or blank caption = all padding = zero states, unconditional).
    ///
    /// # Shapes
    /// - output: `[B, L, D_txt]` with B = `captions.len()`, L = `max_len`
    pub fn encode_text(
        &self,
        tokenizer: &ScratchTokenizer,
        captions: &[String],
        max_len: usize,
        device: &Device,
    ) -> Result<Tensor<3>> {
        let ids = tokenizer.pad_batch(captions, max_len)?;
        Ok(self.text.forward(ids.ids_tensor(device), ids.pad_tensor(device)))
    }
}
