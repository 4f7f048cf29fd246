//! The trained network (MMDiT + scratch caption encoder) and the keyframe masks of docs/method.md §4.5, §5.4.

use any4d_data::keyframes::{KeyframeStrategy, sample_keyframes};
use any4d_model::mmdit::{KfMode, Mmdit, MmditConfig};
use any4d_model::text::scratch::{ScratchTextConfig, ScratchTextModel, ScratchTokenizer};
use burn::module::Module;
use burn::prelude::{Device, Tensor};
use rand::Rng;
use rand::seq::SliceRandom;

use crate::error::{Result, TrainError};

use super::config::{KfSampler, RfSection};

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
        let ids = tokenizer
            .pad_batch(captions, max_len)
            .map_err(|e| TrainError::Other(e.to_string()))?;
        Ok(self.text.forward(ids.ids_tensor(device), ids.pad_tensor(device)))
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Keyframe masks (docs/method.md §4.5, §5.4)

/// The keyframe mask m of one training window of `frames` frames (true = observed keyframe): `Random` draws
/// k ~ U{0..=k_max} and a uniform k-subset (§4.5 steps 1–2); `Scenemi` draws k ~ U{2..=T} with the first and last
/// frames always included (§5.4). Modes trained without keyframes (`replace_noised`, `none`) get all-false masks
/// and consume no random numbers.
pub fn draw_keyframe_mask(rf: &RfSection, kf_mode: KfMode, frames: usize, rng: &mut impl Rng) -> Vec<bool> {
    if !kf_mode.has_mask_channels() {
        return vec![false; frames];
    }
    match rf.kf_sampler {
        KfSampler::Random => sample_keyframes(&KeyframeStrategy::Random { k_max: rf.k_max }, frames, rng),
        KfSampler::Scenemi => {
            let mut mask = vec![false; frames];
            mask[0] = true;
            mask[frames - 1] = true;
            let k = rng.random_range(2..=frames);
            let mut inner: Vec<usize> = (1..frames - 1).collect();
            let (chosen, _) = inner.partial_shuffle(rng, k - 2);
            for &f in chosen.iter() {
                mask[f] = true;
            }
            mask
        }
    }
}
