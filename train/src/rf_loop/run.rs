//! `any4d train rf`: new runs and `--resume`, on one device or data-parallel.

use std::path::{Path, PathBuf};

use any4d_data::io::write_atomic;
use any4d_data::store::{Split, Store};
use any4d_model::mmdit::Anchor;
use any4d_model::text::scratch::ScratchTokenizer;
use burn::prelude::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::backend;
use crate::checkpoint::MODEL_FILE;
use crate::devices::{run_strategy, strategy_note, worker_devices};
use crate::error::{Result, TrainError};
use crate::loop_common::{self, LoopSetup, Objective, Outcome, RunOptions};
use crate::multi_device::train_data_parallel;
use crate::run_folder::{RunFolder, open_for_resume};
use crate::runs::{self, LoadedVae, VaeRunRecord};

use super::RF_TERMS;
use super::batcher::{check_compatible, open_store};
use super::config::{LatentCache, RfRunConfig};
use super::objective::RfObjective;

/// Options of `any4d train rf` besides the config: those of every run, and the frozen VAE.
pub struct RfRunOptions {
    /// Data, run folder, progress, stop flag, devices.
    pub run: RunOptions,
    /// The frozen VAE's run folder (`--vae`): required for a new run; for `--resume` it may be omitted (the run
    /// folder records it) and must otherwise name the same run; with `init` it may be omitted too (the VAE of
    /// that run) and must otherwise name it.
    pub vae_run: Option<PathBuf>,
    /// Start the new run from the newest checkpoint of this RF run or packed folder (`--init`, fine-tuning): its
    /// trained parameters, caption tokenizer and VAE; its `[model]` and `[text]` must equal the new config's. The
    /// optimiser, the step count, the schedule, the random streams and the parameter average start afresh under the
    /// new config.
    pub init: Option<PathBuf>,
    /// The folder of the latent files with `rf.latent_cache = "disk"` (`--latents`): files already current there are
    /// reused, the others encoded into it. Default: `latents/` in the run folder.
    pub latents: Option<PathBuf>,
}

/// The latent files' folder inside a run folder when `--latents` is not given.
pub const LATENTS_DIR: &str = "latents";

/// The file of a run started with `--init` that names the checkpoint folder and step it started from.
pub const INIT_FILE: &str = "init.json";

/// What a run started with `--init` takes from the run it starts from.
struct InitFrom {
    /// The checkpoint folder whose parameters it starts from (canonical).
    checkpoint: PathBuf,
    /// Its step.
    step: u64,
    /// That run's caption tokenizer (the text encoder's embeddings are indexed by it).
    tokenizer: ScratchTokenizer,
    /// That run's VAE.
    vae: VaeRunRecord,
}

impl InitFrom {
    /// Reads `dir` as an RF run and checks that a run of `cfg` can start from it: same network and caption
    /// encoder (`[model]`, `[text]`), and `--vae`, if given, naming its VAE.
    fn open(dir: &Path, cfg: &RfRunConfig, vae_run: Option<&Path>) -> Result<Self> {
        let setup = |reason: String| TrainError::Setup(format!("--init {}: {reason}", dir.display()));
        let own = runs::read_rf_config(dir)?;
        if own.model != cfg.model {
            return Err(setup(format!(
                "its [model] differs from this config's ({}): a run can only start from a network of the same \
                 shape and conditioning",
                differing_keys(&own.model, &cfg.model)
            )));
        }
        if own.text != cfg.text {
            return Err(setup(format!(
                "its [text] differs from this config's ({})",
                differing_keys(&own.text, &cfg.text)
            )));
        }
        let vae = runs::recorded_vae(dir, vae_run)?;
        let tokenizer = ScratchTokenizer::load(dir)?;
        let (checkpoint, step) = runs::newest_checkpoint(dir)?;
        let checkpoint = std::fs::canonicalize(&checkpoint).unwrap_or(checkpoint);
        if !checkpoint.join(MODEL_FILE).is_file() {
            return Err(setup(format!("{} has no {MODEL_FILE}", checkpoint.display())));
        }
        Ok(Self {
            checkpoint,
            step,
            tokenizer,
            vae,
        })
    }
}

/// The keys of two config sections that differ, `key: a → b`, for an error message.
fn differing_keys<T: serde::Serialize>(a: &T, b: &T) -> String {
    let (Ok(a), Ok(b)) = (toml::Table::try_from(a), toml::Table::try_from(b)) else {
        return "the differing keys could not be listed".into();
    };
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| {
            let show = |v: Option<&toml::Value>| v.map_or("(absent)".to_string(), ToString::to_string);
            format!("{k}: {} → {}", show(a.get(k)), show(b.get(k)))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Starts a new RF run with `cfg` on the frozen VAE of `opts.vae_run`; returns the run folder and the outcome.
/// The run folder gets `vae_run.json` (which VAE run and checkpoint step) and `tokenizer.json`.
/// With `opts.init` the run starts from that run's parameters, tokenizer and VAE instead.
pub fn train_rf(cfg: &RfRunConfig, opts: &RfRunOptions) -> Result<(RunFolder, Outcome)> {
    // Fail before claiming a run folder when the options, the backend, the store, the VAE run or the run to start
    // from are unusable.
    check_latents_option(cfg, opts)?;
    let devices = worker_devices(&cfg.device, &cfg.train, opts.run.parallel.as_ref())?;
    let store = open_store(&opts.run.data)?;
    let init = opts
        .init
        .as_deref()
        .map(|dir| InitFrom::open(dir, cfg, opts.vae_run.as_deref()))
        .transpose()?;
    let vae = match &init {
        Some(init) => init.vae.load(&devices[0])?,
        None => {
            let vae_dir = opts
                .vae_run
                .as_deref()
                .ok_or_else(|| TrainError::Setup("a new RF run needs the VAE run folder (--vae RUN)".into()))?;
            runs::load_vae_run(vae_dir, &devices[0])?
        }
    };
    check_compatible(cfg, &store, &vae)?;
    let (tokenizer, note, checkpoint) = match init {
        Some(init) => {
            let note = format!(
                "starts from {} (step {}): its trained parameters, tokenizer ({} tokens) and VAE",
                init.checkpoint.display(),
                init.step,
                init.tokenizer.vocab_size()
            );
            (init.tokenizer, note, Some((init.checkpoint, init.step)))
        }
        None => {
            let captions = train_captions(&store)?;
            let tokenizer = ScratchTokenizer::train(&captions, cfg.text.vocab_size)?;
            let note = format!(
                "tokenizer trained on {} TRAIN captions: {} tokens",
                captions.len(),
                tokenizer.vocab_size()
            );
            (tokenizer, note, None)
        }
    };

    let run = RunFolder::create(&opts.run.runs_dir, &opts.run.name, &cfg.to_toml()?, &RF_TERMS)?;
    runs::write_vae_record(&run, &VaeRunRecord::of(&vae)?)?;
    tokenizer.save(run.root())?;
    run.log(&note)?;
    let start = match checkpoint {
        Some((ckpt, step)) => {
            // Where the parameters came from, for provenance: the checkpoint folder and its step.
            let record = serde_json::json!({ "checkpoint": ckpt.display().to_string(), "step": step });
            write_atomic(&run.path(INIT_FILE), record.to_string().as_bytes())?;
            Start::Init(ckpt)
        }
        None => Start::Fresh,
    };
    let outcome = run_rf(cfg, &run, opts, &vae, tokenizer, &devices, start)?;
    Ok((run, outcome))
}

/// Where a run's parameters come from.
enum Start {
    /// Fresh, from the seed.
    Fresh,
    /// Resumed from this checkpoint of the run itself.
    Resume(PathBuf),
    /// Step 0 from this checkpoint of another run (`--init`).
    Init(PathBuf),
}

/// Continues the RF run in `run_dir` from its newest checkpoint (config, tokenizer and VAE run from the run
/// folder; the backend may be overridden).
pub fn resume_rf(run_dir: &Path, backend: Option<backend::Backend>, opts: &RfRunOptions) -> Result<Outcome> {
    if opts.init.is_some() {
        return Err(TrainError::Setup(
            "a resumed run keeps its own parameters: --init starts a new run".into(),
        ));
    }
    let (run, cfg, ckpt) = open_for_resume(run_dir, RfRunConfig::parse, backend, |c: &mut RfRunConfig| {
        &mut c.device
    })?;
    check_latents_option(&cfg, opts)?;
    let record = runs::recorded_vae(run_dir, opts.vae_run.as_deref())?;
    let devices = worker_devices(&cfg.device, &cfg.train, opts.run.parallel.as_ref())?;
    let vae = record.load(&devices[0])?;
    let tokenizer = ScratchTokenizer::load(run_dir)?;
    run_rf(&cfg, &run, opts, &vae, tokenizer, &devices, Start::Resume(ckpt))
}

/// `--latents` names the folder of the latent files: with another cache it would be ignored, so it is refused.
fn check_latents_option(cfg: &RfRunConfig, opts: &RfRunOptions) -> Result<()> {
    match (&opts.latents, cfg.rf.latent_cache) {
        (Some(dir), cache) if cache != LatentCache::Disk => Err(TrainError::Setup(format!(
            "--latents {} holds latent files, read only with rf.latent_cache = \"disk\" (this run's is {cache:?}): \
             add --set rf.latent_cache=\"disk\" or drop --latents",
            dir.display()
        ))),
        _ => Ok(()),
    }
}

fn train_captions(store: &Store) -> Result<Vec<String>> {
    Ok(store.captions(&store.indices(Split::Train))?)
}

fn run_rf(
    cfg: &RfRunConfig,
    run: &RunFolder,
    opts: &RfRunOptions,
    vae: &LoadedVae,
    tokenizer: ScratchTokenizer,
    devices: &[Device],
    start: Start,
) -> Result<Outcome> {
    let (resume, init) = match start {
        Start::Fresh => (None, None),
        Start::Resume(ckpt) => (Some(ckpt), None),
        Start::Init(ckpt) => (None, Some(ckpt)),
    };
    let vocab = tokenizer.vocab_size();
    let latents = opts.latents.clone().unwrap_or_else(|| run.path(LATENTS_DIR));
    let mut objective = RfObjective::new(cfg, &opts.run.data, Some(&latents), vae, tokenizer, &devices[0])?;
    if let Some(note) = objective.batcher().latent_files_note() {
        run.log(note)?;
    }
    objective.log_validation_samples(run)?;
    if let Anchor::KeyframeLerp { scale } = cfg.model.anchor {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.train.seed);
        let clips = cfg.train.batch_size;
        if let Some(rms) = objective.batcher().anchor_residual_rms(clips, &mut rng, &devices[0])? {
            run.log(&format!(
                "anchor: Z − A has RMS {rms:.4} on the generated slots of the first {clips} TRAIN windows \
                 (standardized posterior means); model.anchor scale s = {scale}"
            ))?;
        }
    }
    run.log(&format!(
        "RF {:?} on {} ({} train clips in {} windows / {} val clips, latents {:?}: {:.1} MiB), VAE {} step {}, backend {}",
        cfg.model.conditioning,
        opts.run.data.display(),
        objective.train_len(),
        objective.train_windows(),
        objective.valid_len(),
        cfg.rf.latent_cache,
        objective.cached_bytes() as f64 / (1024.0 * 1024.0),
        vae.run.display(),
        vae.step,
        cfg.device.backend
    ))?;
    let ad: Vec<Device> = devices.iter().map(|d| d.clone().autodiff()).collect();
    ad[0].seed(cfg.train.seed);
    let model = cfg.model_config(vocab).init(&ad[0]);
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: ad[0].clone(),
        stop: opts.run.stop.clone(),
        progress: opts.run.progress,
        resume,
        init,
    };
    let parallel = opts.run.parallel.as_ref();
    let (_, outcome) = match run_strategy(devices, parallel) {
        Some(strategy) => {
            run.log(&strategy_note(devices, parallel, strategy))?;
            train_data_parallel(&objective, model, setup, &ad, strategy)?
        }
        None => loop_common::train(&objective, model, setup)?,
    };
    Ok(outcome)
}
