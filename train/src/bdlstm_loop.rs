//! `any4d train bdlstm`: the BD-LSTM baseline in its latent adaptation (docs/method.md §5.3) on a frozen frame-wise
//! VAE. Each frame is the VAE's standardised trajectory latent z_f (`[P, C]`, FPS token order); a training example
//! is a random sub-window of n frames of one clip, both chains run free from its first and last frame, and the
//! loss is (B1)–(B3). The run folder records its VAE (`vae_run.json`) like an RF run.

use std::path::{Path, PathBuf};

use any4d_data::acap::{ACAP_CHANNELS, ScalingGranularity};
use any4d_data::store::{Split, Store};
use any4d_model::bdlstm::{
    BdLstm, BdLstmConfig, BdLstmLossConfig, FrameCodec, LatentCodec, LatentCodecConfig, MergeConfig, MeshConvCodec,
    MeshConvCodecConfig, bdlstm_loss, l2_penalty,
};
use any4d_model::latent_stats::LatentStats;
use any4d_model::mesh_vae::Posterior;
use burn::prelude::{Device, Module, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::resolve;
use crate::config::{DeviceConfig, OptimConfig, TrainConfig, to_toml};
use crate::data_order::WholeClips;
use crate::devices::run_devices;
use crate::error::{Result, TrainError, io_err, run_err};
use crate::loop_common::{self, LoopSetup, Losses, Objective, Outcome, RunOptions};
use crate::rf_loop::{LatentDraw, LatentSet, encode_latents_on_workers};
use crate::run_folder::{CONFIG_FILE, RunFolder};
use crate::runs::{self, LoadedVae, VaeRunRecord};

/// Loss terms of a BD-LSTM run (`metrics.csv` columns before `loss`).
pub const BDLSTM_TERMS: [&str; 4] = ["recon", "bidir", "kl", "l2"];

/// What one frame of a BD-LSTM chain is (docs/method.md §5.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BdlstmVariant {
    /// The frozen frame-wise VAE's standardised trajectory latents (our adaptation; any store).
    #[default]
    Latent,
    /// Per-vertex ACAP features with mesh convolutions (the original; one fixed topology).
    Acap,
}

fn default_conv_layers() -> usize {
    3
}

fn default_acap_scaling() -> ScalingGranularity {
    ScalingGranularity::PerVertexChannel
}

/// The `[model]` table: the codec and recurrent sizes (P and C come from the VAE run, N from the store).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BdlstmModelSection {
    /// Frame representation: `"latent"` (default) or `"acap"` (`any4d train bdlstm --variant acap`).
    #[serde(default)]
    pub variant: BdlstmVariant,
    /// Mesh convolutions of the ACAP codec's encoder, mirrored by its decoder (3); unused by the latent variant.
    #[serde(default = "default_conv_layers")]
    pub conv_layers: usize,
    /// Per-token width after the latent codec's first layer (docs/method.md §5.3: 16); unused by the ACAP variant.
    pub token_width: usize,
    /// Latent width Z: encoder output, LSTM input and hidden width (128).
    pub latent: usize,
    /// Stacked LSTM layers (3).
    pub layers: usize,
    /// s₀ of the forward chain; the backward chain starts from −s₀ (0.1).
    pub initial_state: f64,
    /// Std of the perturbation of s₀ on a completion retry (0.1).
    pub retry_noise: f64,
}

/// The `[bdlstm]` table: windows, losses and the completion merge rule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BdlstmSection {
    /// Shortest training sub-window n (3: one frame to fill).
    pub min_window: usize,
    /// Longest training sub-window; 0 = the store's frames T.
    pub max_window: usize,
    /// Which VAE latent the frames are: the posterior mean (what completion encodes keyframes with) or a sample.
    pub latent: LatentDraw,
    /// Weight of (B2) L_bidir (0.5).
    pub bidir_weight: f64,
    /// Weight of L_KL (0.1).
    pub kl_weight: f64,
    /// Weight of Σw² (0.1).
    pub l2_weight: f64,
    /// Merge rule: a try is accepted when the closest aligned pair is nearer than this fraction of the bbox
    /// diagonal (0.05).
    pub merge_threshold: f64,
    /// Merge rule: tries per segment, the first with the nominal initial states (8).
    pub merge_tries: usize,
    /// ACAP variant: the ranges that scale the features to [−0.95, 0.95], `"per_vertex_channel"` (default: every
    /// feature dimension of the fixed topology, as the original) or `"per_channel"`.
    #[serde(default = "default_acap_scaling")]
    pub acap_scaling: ScalingGranularity,
}

/// A whole `configs/bdlstm/*.toml` run config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BdlstmRunConfig {
    /// `[model]`.
    pub model: BdlstmModelSection,
    /// `[bdlstm]`.
    pub bdlstm: BdlstmSection,
    /// `[train]`.
    pub train: TrainConfig,
    /// `[optim]`.
    pub optim: OptimConfig,
    /// `[device]`.
    pub device: DeviceConfig,
}

impl BdlstmRunConfig {
    /// Parses and validates a resolved BD-LSTM run config; errors name `file` and the dotted key.
    pub fn from_table(table: toml::Table, file: &Path) -> Result<Self> {
        let cfg: BdlstmRunConfig = resolve::from_table(table, file)?;
        let bad = |reason: String| TrainError::Config {
            path: file.to_path_buf(),
            reason,
        };
        cfg.train.validate(file)?;
        cfg.optim.validate(file)?;
        let (m, b) = (&cfg.model, &cfg.bdlstm);
        for (name, value) in [
            ("model.token_width", m.token_width),
            ("model.latent", m.latent),
            ("model.layers", m.layers),
            ("model.conv_layers", m.conv_layers),
            ("bdlstm.merge_tries", b.merge_tries),
        ] {
            if value == 0 {
                return Err(bad(format!("{name} must be positive, got 0")));
            }
        }
        for (name, value) in [("model.latent", m.latent), ("model.token_width", m.token_width)] {
            if value > 1 << 16 {
                return Err(bad(format!("{name} = {value} is more than 65536")));
            }
        }
        for (name, value) in [("model.layers", m.layers), ("model.conv_layers", m.conv_layers)] {
            if value > 64 {
                return Err(bad(format!("{name} = {value} is more than 64")));
            }
        }
        for (name, value) in [
            ("model.initial_state", m.initial_state),
            ("model.retry_noise", m.retry_noise),
            ("bdlstm.bidir_weight", b.bidir_weight),
            ("bdlstm.kl_weight", b.kl_weight),
            ("bdlstm.l2_weight", b.l2_weight),
            ("bdlstm.merge_threshold", b.merge_threshold),
        ] {
            if !value.is_finite() {
                return Err(bad(format!("{name} must be finite, got {value}")));
            }
        }
        for (name, value) in [
            ("model.retry_noise", m.retry_noise),
            ("bdlstm.bidir_weight", b.bidir_weight),
            ("bdlstm.kl_weight", b.kl_weight),
            ("bdlstm.l2_weight", b.l2_weight),
            ("bdlstm.merge_threshold", b.merge_threshold),
        ] {
            if value < 0.0 {
                return Err(bad(format!("{name} must be non-negative, got {value}")));
            }
        }
        if b.min_window < 3 {
            return Err(bad(format!(
                "bdlstm.min_window = {} must be at least 3 (a window with a frame to fill)",
                b.min_window
            )));
        }
        if b.max_window != 0 && b.max_window < b.min_window {
            return Err(bad(format!(
                "bdlstm.max_window = {} is less than bdlstm.min_window = {} (0 = the clip length)",
                b.max_window, b.min_window
            )));
        }
        Ok(cfg)
    }

    crate::config::loading_methods!();

    /// The fully resolved config as TOML.
    pub fn to_toml(&self) -> Result<String> {
        to_toml(self)
    }

    /// The recurrent part (layers, initial state, retry noise); the codec carries the widths.
    fn recurrent(&self) -> BdLstmConfig {
        BdLstmConfig::new()
            .with_layers(self.model.layers)
            .with_initial_state(self.model.initial_state)
            .with_retry_noise(self.model.retry_noise)
    }

    /// One training window for a batch of `clips` clips of `frames` frames: its length n ~
    /// U{min_window..=max_window} and one start per clip, both from `rng`.
    pub(crate) fn draw_window(&self, frames: usize, clips: usize, rng: &mut ChaCha8Rng) -> (usize, Vec<usize>) {
        let n = rng.random_range(self.bdlstm.min_window..=self.max_window(frames));
        let starts = (0..clips).map(|_| rng.random_range(0..=frames - n)).collect();
        (n, starts)
    }

    /// The network for latents of `tokens` × `channels` (the VAE's P and C) on `device`.
    pub fn init(&self, tokens: usize, channels: usize, device: &Device) -> BdLstm<LatentCodec> {
        let m = &self.model;
        let codec = LatentCodecConfig::new()
            .with_tokens(tokens)
            .with_channels(channels)
            .with_token_width(m.token_width)
            .with_latent(m.latent)
            .init(device);
        self.recurrent().init(codec, device)
    }

    /// The ACAP variant's network for a fixed topology of `vertices` vertices on `device`.
    pub fn init_acap(&self, vertices: usize, device: &Device) -> BdLstm<MeshConvCodec> {
        let m = &self.model;
        let codec = MeshConvCodecConfig::new(vertices)
            .with_channels(ACAP_CHANNELS)
            .with_conv_layers(m.conv_layers)
            .with_latent(m.latent)
            .init(device);
        self.recurrent().init(codec, device)
    }

    /// The weights of (B3).
    pub fn loss_config(&self) -> BdLstmLossConfig {
        BdLstmLossConfig::new()
            .with_bidir_weight(self.bdlstm.bidir_weight)
            .with_kl_weight(self.bdlstm.kl_weight)
            .with_l2_weight(self.bdlstm.l2_weight)
    }

    /// The completion merge rule.
    pub fn merge_config(&self) -> MergeConfig {
        MergeConfig::new()
            .with_threshold(self.bdlstm.merge_threshold)
            .with_max_tries(self.bdlstm.merge_tries)
    }

    /// The longest training window on clips of `frames` frames.
    pub fn max_window(&self, frames: usize) -> usize {
        match self.bdlstm.max_window {
            0 => frames,
            w => w.min(frames),
        }
    }
}

/// The BD-LSTM objective: frozen-VAE latents of the TRAIN and VAL clips in host memory, standardised by the VAE's
/// statistics (docs/method.md §3.4); terms (B1), (B2), KL and Σw².
pub struct BdlstmObjective {
    cfg: BdlstmRunConfig,
    stats: LatentStats,
    train: LatentSet,
    valid: LatentSet,
    train_clips: WholeClips,
}

impl BdlstmObjective {
    /// Encodes the store's clips with the frozen VAE (on the inference `device`).
    pub fn new(cfg: &BdlstmRunConfig, data: &Path, vae: &LoadedVae, device: &Device) -> Result<Self> {
        let store = open_store(data, cfg, vae)?;
        vae.frame_vae()?;
        let workers = cfg.device.backend.encoding_workers();
        let encode = |split: Split| {
            let indices = store.indices(split);
            encode_latents_on_workers(
                &vae.model,
                &store,
                &indices,
                cfg.train.micro_batch,
                vae.tokens(),
                device,
                workers,
                None,
            )
        };
        let (train, valid) = (encode(Split::Train)?, encode(Split::Val)?);
        let train_clips = WholeClips::new(store.whole_clips(&store.indices(Split::Train))?);
        Ok(Self {
            cfg: cfg.clone(),
            stats: vae.stats,
            train,
            valid,
            train_clips,
        })
    }

    /// Number of VAL clips.
    pub fn valid_len(&self) -> usize {
        self.valid.clips.len()
    }

    /// Host bytes of the cached latents.
    pub fn cached_bytes(&self) -> usize {
        self.train.bytes() + self.valid.bytes()
    }

    /// Standardised latents of frames `start..start + n` of each listed clip of `set`, `[B, n, P, C]`; with
    /// [`LatentDraw::Sample`] each value is μ + σξ with ξ from `rng`.
    fn window(
        &self,
        set: &LatentSet,
        clips: &[usize],
        starts: &[usize],
        n: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> Tensor<4> {
        let frame = set.tokens * set.channels;
        let mut values = Vec::with_capacity(clips.len() * n * frame);
        for (&c, &s) in clips.iter().zip(starts) {
            let clip = &set.clips[c];
            let range = s * frame..(s + n) * frame;
            match self.cfg.bdlstm.latent {
                LatentDraw::Mean => values.extend_from_slice(&clip.mu[range]),
                LatentDraw::Sample => values.extend(
                    clip.mu[range.clone()]
                        .iter()
                        .zip(&clip.logvar[range])
                        .map(|(&mu, &logvar)| {
                            mu + (0.5 * logvar).exp() * any4d_model::noise::standard_normal(rng) as f32
                        }),
                ),
            }
        }
        let raw = Tensor::<4>::from_data(
            TensorData::new(values, [clips.len(), n, set.tokens, set.channels]),
            device,
        );
        self.stats.standardize_motion(raw)
    }

    fn losses(&self, model: &BdLstm<LatentCodec>, window: Tensor<4>, posterior: Posterior) -> Losses {
        chain_losses(model, window, &(), posterior, &self.cfg.loss_config())
    }
}

/// (B3) and its terms of both chains over `window` (`[B, n, K, C]`), from the nominal initial states.
pub(crate) fn chain_losses<C: Module + FrameCodec + burn::module::ModuleDisplay>(
    model: &BdLstm<C>,
    window: Tensor<4>,
    ctx: &C::Context,
    posterior: Posterior,
    cfg: &BdLstmLossConfig,
) -> Losses {
    let [b, ..] = window.dims();
    let device = window.device();
    let init = model.initial_states(b, &device);
    let out = model.forward(window.clone(), &init, ctx, posterior);
    let l2 = l2_penalty(model, &device);
    let loss = bdlstm_loss(&out, window, l2, cfg);
    Losses {
        total: loss.total,
        terms: vec![loss.recon, loss.bidir, loss.kl, loss.l2],
    }
}

/// Validation of a BD-LSTM objective: the losses of `n` VAL clips taken `micro_batch` at a time (each chunk's
/// losses from `losses`, given its positions), averaged with the chunk sizes as weights; terms then total.
pub(crate) fn validate_chunks(
    n: usize,
    micro_batch: usize,
    mut losses: impl FnMut(&[usize]) -> Result<Losses>,
) -> Result<Option<Vec<f64>>> {
    if n == 0 {
        return Ok(None);
    }
    let mut sums = [0.0f64; BDLSTM_TERMS.len() + 1];
    let positions: Vec<usize> = (0..n).collect();
    for chunk in positions.chunks(micro_batch) {
        let l = losses(chunk)?;
        let w = chunk.len() as f64 / n as f64;
        for (s, v) in sums.iter_mut().zip(l.terms.into_iter().chain([l.total])) {
            *s += w * loop_common::scalar(v);
        }
    }
    Ok(Some(sums.to_vec()))
}

impl Objective for BdlstmObjective {
    type Model = BdLstm<LatentCodec>;

    fn terms(&self) -> Vec<String> {
        BDLSTM_TERMS.iter().map(|s| s.to_string()).collect()
    }

    fn train_len(&self) -> usize {
        self.train_clips.len()
    }

    /// One window length n ~ U{min_window..=max_window} per batch, one start per clip, posterior samples inside the
    /// chains' encoder.
    fn loss(&self, model: &Self::Model, indices: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let clips = self.train_clips.draw(indices, rng);
        let (n, starts) = self.cfg.draw_window(self.train.frames, clips.len(), rng);
        let window = self.window(&self.train, &clips, &starts, n, rng, device);
        Ok(self.losses(model, window, Posterior::Sample))
    }

    /// (B3) and its terms on every VAL clip's whole window (posterior means, nominal initial states).
    fn validate(&self, model: &Self::Model, device: &Device, _step: u64) -> Result<Option<Vec<f64>>> {
        let seed = loop_common::step_seed(self.cfg.train.seed, u64::MAX);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        device.seed(seed);
        validate_chunks(self.valid.clips.len(), self.cfg.train.micro_batch, |chunk| {
            let starts = vec![0; chunk.len()];
            let window = self.window(&self.valid, chunk, &starts, self.valid.frames, &mut rng, device);
            Ok(self.losses(model, window, Posterior::Mean))
        })
    }
}

fn open_store(data: &Path, cfg: &BdlstmRunConfig, vae: &LoadedVae) -> Result<Store> {
    let store = Store::open(data)?;
    vae.check_store(&store)?;
    if store.frames() < cfg.bdlstm.min_window {
        return Err(TrainError::Setup(format!(
            "the store {} holds {}-frame clips, shorter than bdlstm.min_window = {}",
            data.display(),
            store.frames(),
            cfg.bdlstm.min_window
        )));
    }
    Ok(store)
}

/// Options of `any4d train bdlstm` besides the config: those of every run and the frozen VAE (required for a new
/// run; with `--resume` optional and then checked against the run's record).
pub struct BdlstmRunOptions {
    /// Data, run folder, progress, stop flag (data-parallel devices are not supported).
    pub run: RunOptions,
    /// The frozen VAE's run folder (`--vae`).
    pub vae_run: Option<PathBuf>,
}

/// Starts a new BD-LSTM run of the latent variant with `cfg` on the frozen VAE of `opts.vae_run` (the entry of both
/// variants is `bdlstm::train_bdlstm`).
pub(crate) fn train_latent(cfg: &BdlstmRunConfig, opts: &BdlstmRunOptions) -> Result<(RunFolder, Outcome)> {
    let vae_dir = opts
        .vae_run
        .as_deref()
        .ok_or_else(|| TrainError::Setup("a new BD-LSTM run needs the VAE run folder (--vae RUN)".into()))?;
    let devices = run_devices(&cfg.device, None)?;
    let vae = runs::load_vae_run(vae_dir, &devices[0])?;
    open_store(&opts.run.data, cfg, &vae)?;
    let run = RunFolder::create(&opts.run.runs_dir, &opts.run.name, &cfg.to_toml()?, &BDLSTM_TERMS)?;
    runs::write_vae_record(&run, &VaeRunRecord::of(&vae)?)?;
    let outcome = run_bdlstm(cfg, &run, &opts.run, &vae, &devices[0], None)?;
    Ok((run, outcome))
}

/// Continues the latent-variant run `run` (config `cfg`, read by `bdlstm::resume_bdlstm`) from `ckpt`.
pub(crate) fn resume_latent(
    cfg: &BdlstmRunConfig,
    run: &RunFolder,
    ckpt: PathBuf,
    opts: &BdlstmRunOptions,
) -> Result<Outcome> {
    let record = runs::recorded_vae(run.root(), opts.vae_run.as_deref())?;
    let devices = run_devices(&cfg.device, None)?;
    let vae = record.load(&devices[0])?;
    run_bdlstm(cfg, run, &opts.run, &vae, &devices[0], Some(ckpt))
}

fn run_bdlstm(
    cfg: &BdlstmRunConfig,
    run: &RunFolder,
    opts: &RunOptions,
    vae: &LoadedVae,
    device: &Device,
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    let objective = BdlstmObjective::new(cfg, &opts.data, vae, device)?;
    run.log(&format!(
        "BD-LSTM (latent) on {} ({} train clips / {} val clips, latents {:.1} MiB), VAE {} step {}, backend {}",
        opts.data.display(),
        objective.train_len(),
        objective.valid_len(),
        objective.cached_bytes() as f64 / (1024.0 * 1024.0),
        vae.run.display(),
        vae.step,
        cfg.device.backend
    ))?;
    let ad = device.clone().autodiff();
    ad.seed(cfg.train.seed);
    let model = cfg.init(vae.tokens(), vae.latent_channels(), &ad);
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: ad,
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
        init: None,
    };
    let (_, outcome) = loop_common::train(&objective, model, setup)?;
    Ok(outcome)
}

/// A trained BD-LSTM run ready for completion.
pub struct LoadedBdlstm {
    /// The network with the newest checkpoint's parameters (the average when the run keeps one).
    pub model: BdLstm<LatentCodec>,
    /// The run's resolved config.
    pub config: BdlstmRunConfig,
    /// The VAE run it was trained on (its recorded checkpoint, loaded: it sizes the codec and decodes completions).
    pub vae: LoadedVae,
    /// The run folder (canonical path).
    pub run: PathBuf,
    /// Its newest checkpoint's step.
    pub step: u64,
}

/// Loads a BD-LSTM run onto `device`: `config.toml`, `vae_run.json` (the VAE's P and C size the codec) and the
/// newest checkpoint.
pub fn load_bdlstm_run(run_dir: &Path, device: &Device) -> Result<LoadedBdlstm> {
    let (run, config) = read_bdlstm_config(run_dir)?;
    if config.model.variant == BdlstmVariant::Acap {
        return Err(run_err(
            &run,
            "is a BD-LSTM run of the ACAP variant: give it as `--bdlstm-acap RUN` (method `bdlstm_acap`)",
        ));
    }
    let vae = runs::read_vae_record(&run)?.load(device)?;
    let (ckpt, step) = runs::newest_checkpoint(&run)?;
    let model = config.init(vae.tokens(), vae.latent_channels(), device);
    let (model, _) = crate::checkpoint::load_for_sampling(model, &ckpt)?;
    Ok(LoadedBdlstm {
        model,
        config,
        vae,
        run,
        step,
    })
}

/// The canonical run folder and resolved config of the BD-LSTM run in `run_dir` (either variant).
pub(crate) fn read_bdlstm_config(run_dir: &Path) -> Result<(PathBuf, BdlstmRunConfig)> {
    let run = std::fs::canonicalize(run_dir).map_err(io_err("open run folder", run_dir))?;
    let config_path = run.join(CONFIG_FILE);
    let text = std::fs::read_to_string(&config_path).map_err(io_err("read", &config_path))?;
    let is_bdlstm = text.parse::<toml::Table>().map_or(true, |t| t.contains_key("bdlstm"));
    if !is_bdlstm {
        return Err(run_err(
            &run,
            "not a BD-LSTM run folder (its config has no [bdlstm] table)",
        ));
    }
    Ok((run, BdlstmRunConfig::parse(&text, &config_path)?))
}
