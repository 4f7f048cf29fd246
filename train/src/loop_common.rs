//! The training loop shared by the VAE (docs/method.md §3.3–3.5) and the RF (docs/method.md §4.5–4.7): gradient
//! accumulation to the global batch, global-norm gradient clipping, AdamW at a constant learning rate, metrics,
//! validation, checkpoints that resume exactly, Ctrl-C, the NaN/Inf guard and the optional parameter average
//! (docs/method.md §4.8). What a step computes is
//! an [`Objective`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::optim::{GradientsAccumulator, GradientsParams, ModuleOptimizer};
use burn::prelude::{Device, Tensor};
use burn::tensor::Gradients;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};

use crate::checkpoint::{self, TrainState};
use crate::config::{OptimConfig, TrainConfig};
use crate::data_order::DataOrder;
use crate::devices::Parallel;
use crate::error::{Result, TrainError};
use crate::grad_clip::clip_global_norm;
use crate::plot;
use crate::progress::{Progress, ProgressMode};
use crate::run_folder::{CHECKPOINTS_DIR, METRICS_FILE, PLOT_FILE, RunFolder, VALID_FILE};

/// Loss of one micro-batch: the total that is differentiated and each named term (scalar tensors, shape [1]).
pub struct Losses {
    /// The optimised loss.
    pub total: Tensor<1>,
    /// One scalar per [`Objective::terms`] name, same order.
    pub terms: Vec<Tensor<1>>,
}

/// What one training step computes.
pub trait Objective {
    /// The trained network.
    type Model: Module + Clone;

    /// Names of the loss terms (the `metrics.csv` columns before `loss`).
    fn terms(&self) -> Vec<String>;

    /// Those of [`Objective::terms`] that are diagnostics, not losses: left out of the loss plot.
    fn diagnostic_terms(&self) -> Vec<String> {
        Vec::new()
    }

    /// Number of training examples.
    fn train_len(&self) -> usize;

    /// Training examples per shard of the store, in example order ([`crate::data_order::WholeClips::blocks`]);
    /// one block, all of them, unless the objective reads a sharded store.
    fn train_blocks(&self) -> Result<Vec<usize>> {
        Ok(vec![self.train_len()])
    }

    /// Loss of the training examples `indices` on the autodiff `device`. All randomness comes from `rng` or
    /// from the device RNG, which the loop reseeds from (seed, step) before every step.
    fn loss(&self, model: &Self::Model, indices: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses>;

    /// Mean validation terms followed by the total, computed with `model` (inference mode) on `device` after
    /// optimiser step `step`; `None` when there is no validation set.
    fn validate(&self, model: &Self::Model, device: &Device, step: u64) -> Result<Option<Vec<f64>>>;
}

/// Set by Ctrl-C (or a test); the loop checks it before every step, saves a checkpoint and returns.
#[derive(Clone, Debug, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Asks the loop to stop after the current step.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    /// Whether a stop was requested.
    pub fn is_set(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Options of a training run besides its config: where the data and the run folder are, how progress shows, the
/// stop flag and the optional data-parallel devices (`any4d train vae|rf`).
pub struct RunOptions {
    /// Store folder (`--data`).
    pub data: PathBuf,
    /// Folder that holds run folders (`--runs-dir`, `runs/`).
    pub runs_dir: PathBuf,
    /// Run name (`--run`): the run goes to `<runs_dir>/<name>-<n>/`.
    pub name: String,
    /// Progress display.
    pub progress: ProgressMode,
    /// Ctrl-C flag.
    pub stop: StopFlag,
    /// Data-parallel devices (`--devices`, `--strategy`); `None` trains on `[device] backend`.
    pub parallel: Option<Parallel>,
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// All steps done; the final checkpoint.
    Finished { steps: u64, checkpoint: PathBuf },
    /// Stopped by the [`StopFlag`] after `step` steps; the checkpoint written then.
    Interrupted { step: u64, checkpoint: PathBuf },
}

/// Everything the loop needs besides the objective and the model.
pub struct LoopSetup<'a> {
    /// The run folder it writes to.
    pub run: &'a RunFolder,
    /// `[train]`.
    pub train: &'a TrainConfig,
    /// `[optim]`.
    pub optim: &'a OptimConfig,
    /// The autodiff training device.
    pub device: Device,
    /// Ctrl-C flag.
    pub stop: StopFlag,
    /// Progress display.
    pub progress: ProgressMode,
    /// Continue from this checkpoint folder instead of starting at step 0.
    pub resume: Option<PathBuf>,
    /// Start at step 0 from the trained parameters of this checkpoint folder instead of fresh ones (fine-tuning);
    /// the optimiser, the step count, the schedule, every random stream and the parameter average (from the loaded
    /// parameters, with its usual warm-up) start afresh. Not with `resume`.
    pub init: Option<PathBuf>,
}

/// Trains `model` with `objective` on `setup.device` until the configured duration, a stop request or a
/// non-finite value. Returns the model to sample with (the parameter average when `train.ema_decay > 0`, else the
/// trained parameters) and how the run ended. Checkpoints go to `run/checkpoints/`.
pub fn train<O: Objective>(objective: &O, model: O::Model, setup: LoopSetup<'_>) -> Result<(O::Model, Outcome)> {
    materialise(&model, &setup.device, setup.train.seed);
    let one = OneDevice(setup.device.clone());
    run_steps(objective, model, setup, &one)
}

/// Draws every lazily initialised parameter of `model` now, from `device`'s stream seeded with `seed`. burn
/// initialises a parameter when it is first read; left to that, the initial weights would depend on what drew from
/// the stream before (the first step's forward pass on one device, a fork onto each worker on several). Here they
/// are a function of the seed alone, the same for every device list.
pub(crate) fn materialise<M: Module>(model: &M, device: &Device, seed: u64) {
    struct Touch;
    impl ModuleVisitor for Touch {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let _ = param.val();
        }
    }
    device.seed(seed);
    model.visit(&mut Touch);
}

/// How one step's gradients are computed from its micro-batches: the only part of the loop that differs
/// between one device ([`OneDevice`]) and several (the `multi_device` module, above this one).
pub(crate) trait StepGradients<O: Objective> {
    /// The autodiff devices; the first holds the model, the optimiser state and validation. Each is reseeded
    /// from (seed, step) before every step.
    fn devices(&self) -> &[Device];

    /// Runs the step's `cfg.accumulation()` micro-batches (taking their indices from `state.order` and host
    /// randomness from `state.rng`), records each one's losses in `losses` and returns the gradients of the
    /// batch-weighted total on the first device.
    fn gradients(
        &self,
        objective: &O,
        model: &O::Model,
        state: &mut TrainState,
        cfg: &TrainConfig,
        losses: &mut StepLosses<'_>,
    ) -> Result<GradientsParams>;
}

/// The single-device step: micro-batches one after another, gradients accumulated in place.
struct OneDevice(Device);

impl<O: Objective> StepGradients<O> for OneDevice {
    fn devices(&self) -> &[Device] {
        std::slice::from_ref(&self.0)
    }

    fn gradients(
        &self,
        objective: &O,
        model: &O::Model,
        state: &mut TrainState,
        cfg: &TrainConfig,
        losses: &mut StepLosses<'_>,
    ) -> Result<GradientsParams> {
        let mut accum = GradientsAccumulator::<O::Model>::new();
        for _ in 0..cfg.accumulation() {
            let idx = state.order.take(cfg.micro_batch);
            // A generator per micro-batch, seeded from the run's, as each data-parallel worker gets: one device and
            // several draw the same numbers for the same micro-batches.
            let mut rng = ChaCha8Rng::seed_from_u64(state.rng.next_u64());
            let (micro, grads) = micro_batch(objective, model, &idx, &mut rng, &self.0, cfg)?;
            losses.record(&micro)?;
            accum.accumulate(model, GradientsParams::from_grads(grads, model));
        }
        Ok(accum.grads())
    }
}

/// The losses one micro-batch contributes to a step.
pub(crate) struct MicroLoss {
    /// Its share of the global batch (micro-batch size / batch size).
    pub weight: f64,
    /// The unweighted loss terms.
    pub terms: Vec<f64>,
    /// The weighted total (`weight · total`), the value that was differentiated.
    pub total: f64,
}

/// Loss and backward pass of the training examples `idx` on `device`: the losses and the gradients of the weighted
/// total (the one place where a micro-batch's loss is weighted by its share of the global batch).
pub(crate) fn micro_batch<O: Objective>(
    objective: &O,
    model: &O::Model,
    idx: &[usize],
    rng: &mut ChaCha8Rng,
    device: &Device,
    cfg: &TrainConfig,
) -> Result<(MicroLoss, Gradients)> {
    let out = objective.loss(model, idx, rng, device)?;
    let weight = idx.len() as f64 / cfg.batch_size as f64;
    let terms: Vec<f64> = out.terms.into_iter().map(scalar).collect();
    let scaled = out.total.mul_scalar(weight);
    let total = scalar(scaled.clone());
    Ok((MicroLoss { weight, terms, total }, scaled.backward()))
}

/// The losses of one step's micro-batches: batch-weighted sums, each value checked by the NaN/Inf guard.
pub(crate) struct StepLosses<'a> {
    step: u64,
    names: &'a [String],
    last_good: &'a Option<PathBuf>,
    /// Σ weight·term per term, then Σ weight·total.
    sums: Vec<f64>,
}

impl StepLosses<'_> {
    /// Adds one micro-batch; an error unless the objective returned one value per declared term.
    pub(crate) fn record(&mut self, micro: &MicroLoss) -> Result<()> {
        let MicroLoss {
            weight,
            ref terms,
            total: scaled_total,
        } = *micro;
        let n = self.names.len();
        if terms.len() != n {
            return Err(TrainError::Loop(format!(
                "objective returned {} loss terms, declared {n}",
                terms.len()
            )));
        }
        for (i, &v) in terms.iter().enumerate() {
            guard(v, self.step, &format!("loss term `{}`", self.names[i]), self.last_good)?;
            self.sums[i] += weight * v;
        }
        guard(scaled_total, self.step, "loss", self.last_good)?;
        self.sums[n] += scaled_total;
        Ok(())
    }
}

/// Flush-to-zero for the loop's lifetime (docs/method.md §10) on this thread, which runs the optimiser, and on every
/// thread of the current rayon pool, which runs the single-device steps; dropping it, at the end, on an error or on a
/// stop, clears both again, so what runs after training in the same process (the quickstart's evaluation) computes
/// as if the loop had never flushed.
pub(crate) struct FlushScope;

impl FlushScope {
    pub(crate) fn begin() -> Self {
        Self::set(true);
        Self
    }

    fn set(on: bool) {
        any4d_model::denormals::set_flush_denormals(on);
        rayon::broadcast(|_| any4d_model::denormals::set_flush_denormals(on));
    }
}

impl Drop for FlushScope {
    fn drop(&mut self) {
        Self::set(false);
    }
}

/// The step loop shared by [`train`] and `multi_device::train_data_parallel`; `stepper` computes
/// each step's gradients, `setup.device` is not used.
pub(crate) fn run_steps<O: Objective, S: StepGradients<O>>(
    objective: &O,
    model: O::Model,
    setup: LoopSetup<'_>,
    stepper: &S,
) -> Result<(O::Model, Outcome)> {
    let LoopSetup {
        run,
        train: cfg,
        optim: optim_cfg,
        device: _,
        stop,
        progress,
        resume,
        init,
    } = setup;
    let devices = stepper.devices();
    let Some(main) = devices.first() else {
        return Err(TrainError::Devices("training needs at least one device".into()));
    };
    let ckpt_dir = run.path(CHECKPOINTS_DIR);
    let len = objective.train_len();
    if len == 0 {
        return Err(TrainError::Loop("the training set is empty".into()));
    }
    let _flush = cfg.flush_denormals.then(FlushScope::begin);
    let total_steps = cfg.duration.steps(len, cfg.batch_size);
    let keeps_average = cfg.ema_decay > 0.0;
    if let (Some(_), Some(_)) = (&resume, &init) {
        return Err(TrainError::Loop(
            "a run either resumes or starts from another run's parameters, not both".into(),
        ));
    }
    let order = DataOrder::sharded(cfg.seed, &objective.train_blocks()?, cfg.shuffle_buffer);
    let (mut model, mut optim, mut state, mut ema) = match &resume {
        Some(ckpt) => {
            let (m, o, s) = checkpoint::load(ckpt, model, optim_cfg.init())?;
            let ema = match keeps_average {
                true => Some(checkpoint::load_ema(m.clone(), ckpt)?),
                false => None,
            };
            run.log(&format!("resumed from {} at step {}", ckpt.display(), s.step))?;
            (m, o, s, ema)
        }
        None => {
            let state = TrainState {
                step: 0,
                rng: ChaCha8Rng::seed_from_u64(cfg.seed),
                order: order.clone(),
                best_valid: None,
            };
            let model = match &init {
                Some(ckpt) => {
                    let m = checkpoint::load_model(model, ckpt)?;
                    run.log(&format!("parameters initialised from {}", ckpt.display()))?;
                    m
                }
                None => model,
            };
            // A loaded average is not carried over: the average's warm-up (`ema_decay_at`) would forget it within
            // ten steps anyway.
            let ema = keeps_average.then(|| model.clone());
            (model, optim_cfg.init(), state, ema)
        }
    };
    if state.order.len == len && !state.order.same_layout(&order) {
        return Err(TrainError::Checkpoint {
            path: resume.unwrap_or_default(),
            reason: format!(
                "saved reading {} shards ({:?} examples each) through a shuffle buffer of {}; the data and config now \
                 give {} shards ({:?}) and a buffer of {}: resume on the store and train.shuffle_buffer it trained on",
                state.order.blocks.len().max(1),
                state.order.blocks,
                state.order.buffer,
                order.blocks.len().max(1),
                order.blocks,
                order.buffer
            ),
        });
    }
    if state.order.len != len {
        return Err(TrainError::Checkpoint {
            path: resume.unwrap_or_default(),
            reason: format!(
                "saved with {} training examples, the data now has {len} (an example is a whole clip, all its \
                 windows together, docs/method.md §2.6; a run checkpointed when windows were examples cannot resume)",
                state.order.len
            ),
        });
    }
    let spread = match devices.len() {
        1 => String::new(),
        n => format!(" over {n} devices {devices:?}"),
    };
    run.log(&format!(
        "training {} → {total_steps} steps, batch {} = {} × {} micro-batches{spread}, {len} examples",
        state.step,
        cfg.batch_size,
        cfg.accumulation(),
        cfg.micro_batch
    ))?;
    let mut last_ckpt = checkpoint::latest(&ckpt_dir)?;
    let mut bar = Progress::new(
        progress,
        state.step,
        total_steps,
        std::time::Duration::from_secs_f64(cfg.progress_every_secs),
    );
    let names = objective.terms();
    let n_terms = names.len();

    while state.step < total_steps {
        if stop.is_set() {
            let ckpt = save(&ckpt_dir, &model, ema.as_ref(), &optim, &state, cfg)?;
            run.log(&format!(
                "stopped by request after step {}; checkpoint {}",
                state.step,
                ckpt.display()
            ))?;
            bar.finish();
            finish_plot(run, objective)?;
            return Ok((
                ema.unwrap_or(model),
                Outcome::Interrupted {
                    step: state.step,
                    checkpoint: ckpt,
                },
            ));
        }
        let step = state.step + 1;
        let t0 = Instant::now();
        for d in devices {
            d.seed(step_seed(cfg.seed, step));
        }
        let mut losses = StepLosses {
            step,
            names: &names,
            last_good: &last_ckpt,
            sums: vec![0.0f64; n_terms + 1],
        };
        let grads = stepper.gradients(objective, &model, &mut state, cfg, &mut losses)?;
        let sums = losses.sums;
        let (grads, grad_norm) = clip_global_norm(&model, grads, optim_cfg.grad_clip);
        guard(grad_norm, step, "gradient norm", &last_ckpt)?;
        let lr = optim_cfg.schedule.lr(optim_cfg.lr, step, total_steps);
        model = optim.step(lr, model, grads);
        if let Some(avg) = ema.take() {
            ema = Some(ema_update(avg, &model, ema_decay_at(cfg.ema_decay, step))?);
        }
        state.step = step;

        let secs = t0.elapsed().as_secs_f64();
        let mut row = sums.clone();
        row.extend([lr, grad_norm, 1.0 / secs, cfg.batch_size as f64 / secs]);
        run.append_metrics(step, &row)?;
        bar.step(step, sums[n_terms], secs);

        let mut new_best = false;
        if (step.is_multiple_of(cfg.valid_every) || step == total_steps)
            && let Some(values) = objective.validate(
                &ema.as_ref().unwrap_or(&model).clone().valid(),
                &main.clone().without_autodiff(),
                step,
            )?
        {
            let Some(&loss) = values.last() else {
                return Err(TrainError::Loop("validate returned no values".into()));
            };
            run.append_valid(step, &values)?;
            bar.println(&format!("step {step}: validation loss {loss:.4e}"));
            if state.best_valid.is_none_or(|(_, b)| loss < b) {
                state.best_valid = Some((step, loss));
                new_best = true;
            }
        }
        if step % cfg.checkpoint_every == 0 || step == total_steps || new_best {
            last_ckpt = Some(save(&ckpt_dir, &model, ema.as_ref(), &optim, &state, cfg)?);
        }
    }
    bar.finish();
    let ckpt = match last_ckpt {
        Some(c) if c.ends_with(checkpoint::step_dir_name(state.step)) => c,
        _ => save(&ckpt_dir, &model, ema.as_ref(), &optim, &state, cfg)?,
    };
    run.log(&format!("finished {} steps; checkpoint {}", state.step, ckpt.display()))?;
    finish_plot(run, objective)?;
    Ok((
        ema.unwrap_or(model),
        Outcome::Finished {
            steps: state.step,
            checkpoint: ckpt,
        },
    ))
}

fn save<M: Module + Clone>(
    dir: &Path,
    model: &M,
    ema: Option<&M>,
    optim: &ModuleOptimizer,
    state: &TrainState,
    cfg: &TrainConfig,
) -> Result<PathBuf> {
    let path = checkpoint::save(dir, model, ema, optim, state)?;
    checkpoint::prune(dir, cfg.keep_last, state.best_valid.map(|(s, _)| s))?;
    Ok(path)
}

fn finish_plot<O: Objective + ?Sized>(run: &RunFolder, objective: &O) -> Result<()> {
    plot::plot_run(
        &run.path(METRICS_FILE),
        &run.path(VALID_FILE),
        &run.path(PLOT_FILE),
        &objective.diagnostic_terms(),
    )
}

/// The averaging decay after optimiser step `step` (1-based) for a configured `decay` (docs/method.md §4.8):
/// min(d, (1 + s)/(10 + s)), so that the average forgets the first steps' weights quickly.
pub fn ema_decay_at(decay: f64, step: u64) -> f64 {
    let s = step as f64;
    decay.min((1.0 + s) / (10.0 + s))
}

/// θ̄ ← d θ̄ + (1 − d) θ for every float parameter of `avg`, θ taken from `model` by parameter id
/// (docs/method.md §4.8). `avg` must have been cloned from `model` or loaded next to it, so that every id matches;
/// otherwise an error. No autodiff graph is recorded.
pub fn ema_update<M: Module>(avg: M, model: &M, decay: f64) -> Result<M> {
    struct Current(HashMap<ParamId, Tensor<1>>);
    impl ModuleVisitor for Current {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.insert(param.id, param.val().detach().flatten::<1>(0, D - 1));
        }
    }
    struct Blend {
        current: HashMap<ParamId, Tensor<1>>,
        decay: f64,
        unmatched: usize,
    }
    impl ModuleMapper for Blend {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let Some(now) = self.current.remove(&param.id) else {
                self.unmatched += 1;
                return param;
            };
            let d = self.decay;
            param.map(|avg| {
                let shape = avg.shape();
                avg.detach().mul_scalar(d).add(now.reshape(shape).mul_scalar(1.0 - d))
            })
        }
    }
    let mut current = Current(HashMap::new());
    model.visit(&mut current);
    let mut blend = Blend {
        current: current.0,
        decay,
        unmatched: 0,
    };
    let avg = avg.map(&mut blend);
    if blend.unmatched > 0 || !blend.current.is_empty() {
        return Err(TrainError::Loop(format!(
            "parameter average out of step with the model: {} averaged and {} trained parameters without a partner",
            blend.unmatched,
            blend.current.len()
        )));
    }
    Ok(avg)
}

/// Device seed of `step`: a fixed function of (seed, step), so a resumed run draws the same in-model noise.
pub fn step_seed(seed: u64, step: u64) -> u64 {
    // The SplitMix64 finaliser of seed ⊕ step·φ: nearby steps get unrelated seeds.
    splitmix64(seed ^ step.wrapping_mul(GOLDEN_GAMMA))
}

/// The value of a one-element tensor on the host.
pub fn scalar(t: Tensor<1>) -> f64 {
    f64::from(t.into_scalar::<f32>())
}

fn guard(value: f64, step: u64, what: &str, last_good: &Option<PathBuf>) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(TrainError::NonFinite {
            step,
            what: what.to_string(),
            value,
            last_good: last_good.clone(),
        })
    }
}
