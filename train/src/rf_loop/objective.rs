//! The RF training objective (docs/method.md (R5)): batches from [`RfBatcher`], the loss through
//! `rf_training_loss`, validation of (R5) on the VAL split with a fixed seed and, when switched on, the validation
//! samples of `validation.rs`.

use std::path::Path;

use any4d_model::rectified_flow::rf_training_loss;
use any4d_model::text::scratch::ScratchTokenizer;
use burn::prelude::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::data_order::WholeClips;
use crate::error::Result;
use crate::loop_common::{self, Losses, Objective};
use crate::run_folder::{RunFolder, SAMPLES_FILE};
use crate::runs::LoadedVae;

use super::batcher::{RfBatcher, Subset, TextDropout};
use super::config::RfRunConfig;
use super::network::RfModel;
use super::validation::{ValidSampleScores, validation_samples};
use super::{KF_FRAC_TERM, RF_TERMS, SAMPLE_TERMS};

/// Training objective of the keyframe RF on a frozen VAE: terms `rf` (R5) and `kf_frac`.
pub struct RfObjective {
    batcher: RfBatcher,
    /// The TRAIN windows grouped into whole clips: the training examples (docs/method.md §2.6).
    train_clips: WholeClips,
    /// Where validation samples are logged ([`RfObjective::log_validation_samples`]).
    samples_run: Option<RunFolder>,
}

impl RfObjective {
    /// The objective on the batches of [`RfBatcher::new`].
    pub fn new(
        cfg: &RfRunConfig,
        data: &Path,
        latents: Option<&Path>,
        vae: &LoadedVae,
        tokenizer: ScratchTokenizer,
        device: &Device,
    ) -> Result<Self> {
        let batcher = RfBatcher::new(cfg, data, latents, vae, tokenizer, device)?;
        let train_clips = WholeClips::new(batcher.store().whole_clips(batcher.train_indices())?);
        Ok(RfObjective {
            batcher,
            train_clips,
            samples_run: None,
        })
    }

    /// Its batches.
    pub fn batcher(&self) -> &RfBatcher {
        &self.batcher
    }

    /// Number of TRAIN windows (the examples are the whole clips they come from: [`Objective::train_len`]).
    pub fn train_windows(&self) -> usize {
        self.train_clips.windows()
    }

    /// Number of VAL clips.
    pub fn valid_len(&self) -> usize {
        self.batcher.valid_len()
    }

    /// Host bytes of the cached latents.
    pub fn cached_bytes(&self) -> usize {
        self.batcher.cached_bytes()
    }

    /// Turns on validation sampling into `run` when `rf.valid_sample_every` > 0: creates `samples.csv`
    /// (`step, rmse, chamfer, dtw`) unless a resumed run already has it; from then on every validation at a
    /// multiple of `rf.valid_sample_every` or at the last step appends a row of [`RfObjective::validation_samples`]
    /// and a line to `log.txt`. With `valid_sample_every = 0` nothing is written.
    pub fn log_validation_samples(&mut self, run: &RunFolder) -> Result<()> {
        if self.batcher.config().rf.valid_sample_every == 0 {
            return Ok(());
        }
        run.ensure_table(SAMPLES_FILE, &SAMPLE_TERMS)?;
        self.samples_run = Some(run.clone());
        Ok(())
    }

    /// The validation samples of the current network ([`validation_samples`]).
    pub fn validation_samples(&self, model: &RfModel, device: &Device) -> Result<Option<ValidSampleScores>> {
        validation_samples(&self.batcher, model, device)
    }

    /// At the validation after `step`: samples and logs when [`RfObjective::log_validation_samples`] is on and
    /// `step` is a multiple of `rf.valid_sample_every` or the last step.
    fn sample_at_validation(&self, model: &RfModel, device: &Device, step: u64) -> Result<()> {
        let Some(run) = &self.samples_run else {
            return Ok(());
        };
        let cfg = self.batcher.config();
        let last = cfg.train.duration.steps(self.train_len(), cfg.train.batch_size);
        if !(step.is_multiple_of(cfg.rf.valid_sample_every) || step == last) {
            return Ok(());
        }
        let Some(s) = self.validation_samples(model, device)? else {
            return Ok(());
        };
        run.append_samples(step, &[s.rmse, s.chamfer, s.dtw])?;
        run.log(&format!(
            "step {step}: validation samples ({} clips, {}-point grid): rmse {:.4e}, chamfer {:.4e}, dtw {:.4e}",
            s.clips, cfg.rf.valid_sample_grid, s.rmse, s.chamfer, s.dtw
        ))
    }
}

impl Objective for RfObjective {
    type Model = RfModel;

    fn terms(&self) -> Vec<String> {
        RF_TERMS.iter().map(|s| s.to_string()).collect()
    }

    fn diagnostic_terms(&self) -> Vec<String> {
        vec![KF_FRAC_TERM.to_owned()]
    }

    fn train_len(&self) -> usize {
        self.train_clips.len()
    }

    fn train_blocks(&self) -> Result<Vec<usize>> {
        let (store, train) = (self.batcher.store(), self.batcher.train_indices());
        Ok(self.train_clips.blocks(|pos| store.shard_of(train[pos]))?)
    }

    fn loss(&self, model: &RfModel, indices: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let windows = self.train_clips.draw(indices, rng);
        let step = self
            .batcher
            .batch(model, Subset::Train, &windows, rng, TextDropout::Apply, device)?;
        let kf_frac = step.batch.mask.clone().mean();
        let options = self.batcher.config().loss_options();
        let rf = rf_training_loss(&model.mmdit, &step.batch, step.eps, step.tau, &options); // (R5)
        Ok(Losses {
            total: rf.clone(),
            terms: vec![rf, kf_frac],
        })
    }

    /// (R5) on the VAL split with a fixed seed (same masks, ξ, ε and τ at every validation) and no text dropout;
    /// then, when switched on, the validation samples of [`RfObjective::log_validation_samples`].
    fn validate(&self, model: &RfModel, device: &Device, step: u64) -> Result<Option<Vec<f64>>> {
        let n = self.batcher.valid_len();
        if n == 0 {
            return Ok(None);
        }
        let cfg = self.batcher.config();
        let seed = loop_common::step_seed(cfg.train.seed, u64::MAX);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        device.seed(seed);
        let mut sums = [0.0f64; 3];
        let positions: Vec<usize> = (0..n).collect();
        for chunk in positions.chunks(cfg.train.micro_batch) {
            let step = self
                .batcher
                .batch(model, Subset::Valid, chunk, &mut rng, TextDropout::Off, device)?;
            let kf_frac = step.batch.mask.clone().mean();
            let rf = rf_training_loss(&model.mmdit, &step.batch, step.eps, step.tau, &cfg.loss_options());
            let w = chunk.len() as f64 / n as f64;
            let rf = loop_common::scalar(rf);
            for (s, v) in sums.iter_mut().zip([rf, loop_common::scalar(kf_frac), rf]) {
                *s += w * v;
            }
        }
        self.sample_at_validation(model, device, step)?;
        Ok(Some(sums.to_vec()))
    }
}
