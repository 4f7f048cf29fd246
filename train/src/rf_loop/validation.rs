//! Validation sampling of an RF run: every `rf.valid_sample_every` steps and at the end, a few VAL clips are
//! completed by the current network through the eval crate's sampler (docs/method.md §4.6) and scored with
//! (E1)–(E3) of §6.2 (`samples.csv`), so a run shows how well it completes clips, not only its loss.

use std::sync::Arc;

use any4d_data::batch::PadTo;
use any4d_data::keyframes::sample_keyframes;
use any4d_eval::learned::{LearnedModels, MeshCodec, RfSampler};
use any4d_eval::methods::{AAM_GUIDANCE, KeyframeNoise, MethodKind, RfMethod, complete_and_score_batch};
use any4d_model::mmdit::KeyframeConditioning;
use any4d_model::rectified_flow::SampleOptions;
use any4d_model::text::scratch::{ScratchTextModel, ScratchTokenizer};
use any4d_model::text::{TextBatch, TextEncoder, TextError};
use burn::prelude::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::error::Result;
use crate::loop_common;

use super::VALID_SAMPLE_KEYFRAMES;
use super::batcher::RfBatcher;
use super::network::RfModel;

/// Mean scores of one validation-sampling round (docs/method.md §6 (E1)–(E3), normalised frame of each clip's frame 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidSampleScores {
    /// VAL clips sampled.
    pub clips: usize,
    /// (E1) vertex RMSE on the non-keyframes.
    pub rmse: f64,
    /// (E2) Chamfer distance.
    pub chamfer: f64,
    /// (E3) centroid-trajectory DTW.
    pub dtw: f64,
}

/// The scratch caption encoder during training, as the eval crate's [`TextEncoder`]: the objective's tokenizer
/// (shared, not copied) and the text transformer of the current network.
struct TrainingText {
    tokenizer: Arc<ScratchTokenizer>,
    model: ScratchTextModel,
    max_len: usize,
    dim: usize,
}

impl TextEncoder for TrainingText {
    fn encode(&self, captions: &[String], device: &Device) -> std::result::Result<TextBatch, TextError> {
        let ids = self.tokenizer.pad_batch(captions, self.max_len)?;
        let pad_mask = ids.pad_tensor(device);
        let states = self.model.forward(ids.ids_tensor(device), pad_mask.clone());
        Ok(TextBatch { states, pad_mask })
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn max_len(&self) -> usize {
        self.max_len
    }
}

/// Completes the first `rf.valid_sample_clips` VAL clips of `batcher` with `model` (inference mode, on the
/// inference `device`) and scores them: keyframes [`VALID_SAMPLE_KEYFRAMES`] from a fixed seed, the eval crate's
/// [`RfSampler`] on an `rf.valid_sample_grid`-point midpoint grid with CFG weight 1 (docs/method.md §4.6: (R3) for
/// `input_mask`, the replacement sampler (R7)–(R8) for `replace_noised` and `none`, (R9) with `rf.tau_star` for
/// `impute_until`; on a sequence-wise VAE the AnimateAnyMesh reference of §5.5 with its CFG weight 3), keyframes replaced by the ground truth, then (E1)–(E3) against the clip. Every draw is seeded
/// from `train.seed`, so the same network gives the same scores; the training RNG streams are untouched (the loop
/// reseeds the device before every step). `None` without VAL clips.
pub fn validation_samples(batcher: &RfBatcher, model: &RfModel, device: &Device) -> Result<Option<ValidSampleScores>> {
    let cfg = batcher.config();
    let n = cfg.rf.valid_sample_clips.min(batcher.valid_len());
    if n == 0 {
        return Ok(None);
    }
    // Window length: the RF's frames, or the clips of the sequence-wise VAE (the AnimateAnyMesh reference).
    let frames = batcher.store().frames();
    VALID_SAMPLE_KEYFRAMES.check(frames)?;
    let codec = MeshCodec::new(batcher.vae().clone(), batcher.tokens(), PadTo::BatchMax, device.clone())?;
    let text = TrainingText {
        tokenizer: Arc::clone(batcher.tokenizer()),
        model: model.text.clone(),
        max_len: cfg.text.max_len,
        dim: cfg.model.text_dim,
    };
    let models = LearnedModels::new(
        Arc::new(codec),
        model.mmdit.clone(),
        cfg.model.clone(),
        batcher.stats(),
        Box::new(text),
    )?;
    let aam = batcher.vae().clip_frames().is_some();
    let kind = match cfg.model.conditioning {
        _ if aam => MethodKind::Aam,
        KeyframeConditioning::InputMask => MethodKind::KeyframeRf,
        KeyframeConditioning::ReplaceNoised | KeyframeConditioning::None => MethodKind::ReplacementRf,
        KeyframeConditioning::ImputeUntil => MethodKind::ImputeUntil {
            tau_star: cfg.rf.tau_star as f32,
            keyframes: KeyframeNoise::Clean,
        },
    };
    let mut options = SampleOptions::paper(cfg.model.conditioning);
    options.n_grid = cfg.rf.valid_sample_grid;
    options.tau_star = cfg.rf.tau_star;
    let guidance = if aam { AAM_GUIDANCE } else { 1.0 };
    let sampler = RfSampler::for_method(kind, Arc::new(models), options, guidance)?;
    let method = RfMethod::new(kind, sampler)?;

    // Seeds of their own (u64::MAX is the validation loss's): fixed keyframes and sampler noise per clip.
    let seed = loop_common::step_seed(cfg.train.seed, u64::MAX - 1);
    let mut key_rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sums = [0.0f64; 3];
    for (i, &store_index) in batcher.valid_indices()[..n].iter().enumerate() {
        let item = batcher.store().get(store_index)?;
        let clip = item.clip;
        let keyframes: Vec<usize> = sample_keyframes(&VALID_SAMPLE_KEYFRAMES, frames, &mut key_rng)
            .iter()
            .enumerate()
            .filter_map(|(f, &k)| k.then_some(f))
            .collect();
        let clip_seed = seed.wrapping_add(i as u64);
        device.seed(clip_seed);
        // A scene-aware network is told the clip's scene, as in its training batches.
        let asks = [(keyframes.as_slice(), clip_seed)];
        let scored = complete_and_score_batch(&method, &clip, &asks, &clip.caption, item.scene.as_ref())?;
        let m = &scored[0].metrics;
        for (s, v) in sums.iter_mut().zip([m.rmse, m.chamfer, m.dtw]) {
            *s += v / n as f64;
        }
    }
    Ok(Some(ValidSampleScores {
        clips: n,
        rmse: sums[0],
        chamfer: sums[1],
        dtw: sums[2],
    }))
}
