//! Helpers shared by the train crate's integration tests (and, through `tests/common`, the binary's): the
//! one-at-a-time lock, paths, the small procedural store, the tiny VAE config, a parameter dump, and the toy MLP
//! regression that exercises the generic loop.
// Each test file compiles its own copy of this module and uses only some of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use any4d_data::store::write_synth_with;
use any4d_data::synth::SynthConfig;
use any4d_train::Result;
use any4d_train::config::{Duration, OptimConfig, TrainConfig};
use any4d_train::loop_common::{LoopSetup, Losses, Objective, StopFlag};
use any4d_train::progress::ProgressMode;
use any4d_train::run_folder::RunFolder;
use any4d_train::vae_loop::VaeRunConfig;
use burn::module::{Module, ModuleVisitor, Param};
use burn::nn::{Linear, LinearConfig, Relu};
use burn::prelude::{Device, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// burn's CPU RNG seed is process-wide: tests that train or draw from it run one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// Holds the one-at-a-time lock until dropped (a test that panicked while holding it does not block the rest).
pub fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// The repository root (configs/, scripts/): the nearest folder above this package that holds `configs/`.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|p| p.join("configs").is_dir())
        .expect("the repository root holds configs/")
        .to_path_buf()
}

/// Copies the folder `from` to `to`, recursively (a run folder a test then alters).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.path().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Writes `dir/store`: 10 procedural clips of 4 frames and 256–512 vertices drawn with `seed`, P = 32 FPS points.
pub fn synth_store(dir: &Path, seed: u64) -> PathBuf {
    synth_store_with(dir, seed, false)
}

/// [`synth_store`], each clip in a procedural scene when `scenes` is set.
pub fn synth_store_with(dir: &Path, seed: u64, scenes: bool) -> PathBuf {
    let store = dir.join("store");
    write_synth_with(&synth_config(seed, scenes), &store, 32, None).expect("synthetic store");
    store
}

/// The procedural clips of [`synth_store`]: 10 clips of 4 frames, 256–512 vertices.
fn synth_config(seed: u64, scenes: bool) -> SynthConfig {
    SynthConfig {
        clips: 10,
        seed,
        frames: 4,
        min_vertices: 256,
        max_vertices: 512,
        body: None,
        family: Default::default(),
        scenes,
    }
}

/// The clips of [`synth_store`] as a sharded store of `shards` shards (`dir/sharded`, shard folders inside it).
pub fn sharded_synth_store(dir: &Path, seed: u64, shards: usize) -> PathBuf {
    let store = dir.join("sharded");
    let synth = synth_config(seed, false);
    let dirs: Vec<PathBuf> = (0..shards).map(|k| store.join(format!("shard-{k}"))).collect();
    for (k, d) in dirs.iter().enumerate() {
        let spec = any4d_data::store::ShardSpec {
            index: k,
            count: shards,
        };
        any4d_data::store::write_synth_shard(&synth, d, 32, (4, 1), Some(spec), None).expect("a shard");
    }
    any4d_data::store::merge(&store, &dirs).expect("merged shards");
    store
}

/// configs/vae/tiny.toml for `steps` steps of 4 clips; callers set micro-batches, checkpoints and validation.
pub fn tiny_vae(steps: u64) -> VaeRunConfig {
    let mut cfg = VaeRunConfig::load(&root().join("configs/vae/tiny.toml"), &[]).expect("configs/vae/tiny.toml");
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg
}

/// Options of a quiet one-device run named `name` on `store`, its run folders under `dir/runs`.
pub fn run_options(store: &Path, dir: &Path, name: &str) -> any4d_train::loop_common::RunOptions {
    any4d_train::loop_common::RunOptions {
        data: store.to_path_buf(),
        runs_dir: dir.join("runs"),
        name: name.into(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
        parallel: None,
    }
}

/// A [`LoopSetup`] on `device` that prints nothing, is never asked to stop, and resumes from `resume` when given.
pub fn quiet_setup<'a>(
    run: &'a RunFolder,
    train: &'a TrainConfig,
    optim: &'a OptimConfig,
    device: Device,
    resume: Option<PathBuf>,
) -> LoopSetup<'a> {
    LoopSetup {
        run,
        train,
        optim,
        device,
        stop: StopFlag::new(),
        progress: ProgressMode::Quiet,
        resume,
        init: None,
    }
}

/// Every float parameter of `m`, in visiting order, as f32 (never empty, so equality of two dumps means something).
/// Adds a constant to every float parameter (a second point of the same module, same parameter ids).
pub struct Shift(pub f32);

impl burn::module::ModuleMapper for Shift {
    fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let by = self.0;
        p.map(|t| t.add_scalar(by))
    }
}

pub fn params<M: Module>(m: &M) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            let values = p.val().into_data().convert::<f32>().try_to_vec::<f32>();
            self.0.extend(values.expect("f32 parameters"));
        }
    }
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    assert!(!c.0.is_empty(), "the module has no float parameters to compare");
    c.0
}

/// The toy network: 4 → 16 → ReLU → 1, initialised from device seed 1.
#[derive(Module, Debug)]
pub struct Mlp {
    fc1: Linear,
    fc2: Linear,
    act: Relu,
}

impl Mlp {
    pub fn new(device: &Device) -> Self {
        device.seed(1);
        Mlp {
            fc1: LinearConfig::new(4, 16).init(device),
            fc2: LinearConfig::new(16, 1).init(device),
            act: Relu::new(),
        }
    }
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.fc2.forward(self.act.forward(self.fc1.forward(x)))
    }
}

/// Training examples of [`Toy`]; any further examples are its validation set.
const TOY_TRAIN: usize = 32;

/// y = Σx / 2 on fixed inputs: [`Toy::noisy`] or [`Toy::exact`].
pub struct Toy {
    xs: Vec<[f32; 4]>,
    noisy: bool,
    /// Requests a stop on the given flag during this (1-based) `loss` call.
    pub stop_after_calls: Option<(usize, StopFlag)>,
    /// Makes the loss of this (1-based) `loss` call NaN.
    pub nan_at_call: Option<usize>,
    calls: AtomicUsize,
}

impl Toy {
    /// 32 training and 8 validation examples; the host RNG adds input jitter and the device RNG target noise, so
    /// both random streams must be restored for an exact resume.
    pub fn noisy() -> Self {
        Self::new(TOY_TRAIN + 8, true)
    }

    /// 32 training examples, no randomness and no validation: every loop must see the same data and gradients.
    pub fn exact() -> Self {
        Self::new(TOY_TRAIN, false)
    }

    fn new(examples: usize, noisy: bool) -> Self {
        let xs = (0..examples).map(|i| {
            let f = i as f32;
            [(f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin(), (f * 1.3).cos()]
        });
        Toy {
            xs: xs.collect(),
            noisy,
            stop_after_calls: None,
            nan_at_call: None,
            calls: AtomicUsize::new(0),
        }
    }
}

impl Objective for Toy {
    type Model = Mlp;
    fn terms(&self) -> Vec<String> {
        vec!["mse".into()]
    }
    fn train_len(&self) -> usize {
        TOY_TRAIN
    }
    fn loss(&self, model: &Mlp, idx: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let calls = self.calls.fetch_add(1, Ordering::SeqCst) + 1;
        if let Some((n, flag)) = &self.stop_after_calls
            && calls == *n
        {
            flag.request();
        }
        let mut flat = Vec::new();
        for &i in idx {
            if self.noisy {
                flat.extend(self.xs[i].iter().map(|v| v + rng.random_range(-0.01f32..0.01)));
            } else {
                flat.extend(self.xs[i]);
            }
        }
        let x = Tensor::<2>::from_data(TensorData::new(flat, [idx.len(), 4]), device);
        let mut y = x.clone().sum_dim(1).div_scalar(2.0);
        if self.noisy {
            y = y + Tensor::<2>::random([idx.len(), 1], Distribution::Normal(0.0, 0.01), device);
        }
        let mut mse = (model.forward(x) - y).square().mean();
        if self.nan_at_call == Some(calls) {
            mse = mse.div_scalar(0.0).mul_scalar(0.0);
        }
        Ok(Losses {
            total: mse.clone(),
            terms: vec![mse],
        })
    }
    fn validate(&self, model: &Mlp, device: &Device, _step: u64) -> Result<Option<Vec<f64>>> {
        let valid = &self.xs[TOY_TRAIN..];
        if valid.is_empty() {
            return Ok(None);
        }
        let flat: Vec<f32> = valid.iter().flatten().copied().collect();
        let x = Tensor::<2>::from_data(TensorData::new(flat, [valid.len(), 4]), device);
        let y = x.clone().sum_dim(1).div_scalar(2.0);
        let mse = f64::from((model.forward(x) - y).square().mean().into_scalar::<f32>());
        Ok(Some(vec![mse, mse]))
    }
}

/// The toy loop's configs: seed 666, batches of 8 in micro-batches of 4, checkpoints every 3 steps (2 kept),
/// validation every 4, AdamW at 1e-2 with clipping at 1.
pub fn toy_configs(steps: u64) -> (TrainConfig, OptimConfig) {
    let train = TrainConfig {
        seed: 666,
        duration: Duration::Steps(steps),
        batch_size: 8,
        micro_batch: 4,
        checkpoint_every: 3,
        keep_last: 2,
        valid_every: 4,
        progress_every_secs: 5.0,
        ema_decay: 0.0,
        flush_denormals: true,
        shuffle_buffer: 0,
    };
    let optim = OptimConfig {
        lr: 1e-2,
        schedule: any4d_train::config::LrSchedule::Constant,
        beta1: 0.9,
        beta2: 0.99,
        weight_decay: 0.01,
        eps: 1e-8,
        grad_clip: 1.0,
    };
    (train, optim)
}

/// A procedural store (4-frame clips, P = 32, drawn with `store_seed`) and a finished 6-step tiny VAE run on it, in
/// a temporary folder that lives as long as the fixture: what the RF and BD-LSTM tests train on.
pub struct VaeFixture {
    _dir: tempfile::TempDir,
    /// The temporary folder (runs go to `dir/runs`).
    pub dir: PathBuf,
    /// The store.
    pub store: PathBuf,
    /// The VAE run folder.
    pub vae_run: PathBuf,
}

/// Makes a [`VaeFixture`]; callers keep it in a `OnceLock` so a test process trains the VAE once.
pub fn vae_fixture(store_seed: u64) -> VaeFixture {
    vae_fixture_with(store_seed, tiny_vae(6))
}

/// configs/vae/dymesh_tiny.toml (the sequence-wise VAE of the AnimateAnyMesh reference) for the 4-frame store,
/// `steps` steps of 4 clips.
pub fn tiny_dymesh_vae(steps: u64) -> VaeRunConfig {
    let frames: any4d_train::config::Override = "model.frames=4".parse().expect("override");
    let mut cfg = VaeRunConfig::load(&root().join("configs/vae/dymesh_tiny.toml"), &[frames])
        .expect("configs/vae/dymesh_tiny.toml");
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg
}

/// A [`VaeFixture`] whose 6-step VAE run has the config `cfg` (its micro-batch, checkpoints and validation set here).
pub fn vae_fixture_with(store_seed: u64, cfg: VaeRunConfig) -> VaeFixture {
    vae_fixture_in(store_seed, cfg, false)
}

/// [`vae_fixture_with`] on a store whose clips move in procedural scenes when `scenes` is set.
pub fn vae_fixture_in(store_seed: u64, mut cfg: VaeRunConfig, scenes: bool) -> VaeFixture {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = synth_store_with(dir.path(), store_seed, scenes);
    cfg.train.micro_batch = 4;
    cfg.train.checkpoint_every = 6;
    cfg.train.valid_every = 6;
    let opts = run_options(&store, dir.path(), "vae");
    let (run, outcome) = any4d_train::vae_loop::train_vae(&cfg, &opts).expect("tiny VAE run");
    assert!(
        matches!(outcome, any4d_train::loop_common::Outcome::Finished { .. }),
        "{outcome:?}"
    );
    VaeFixture {
        dir: dir.path().to_path_buf(),
        vae_run: run.root().to_path_buf(),
        store,
        _dir: dir,
    }
}

/// `configs/bdlstm/<preset>` for `steps` steps of 4 clips, checkpointed and validated once at the end.
pub fn bdlstm_preset(preset: &str, steps: u64) -> any4d_train::bdlstm_loop::BdlstmRunConfig {
    let path = root().join("configs/bdlstm").join(preset);
    let mut cfg = any4d_train::bdlstm_loop::BdlstmRunConfig::load(&path, &[]).expect("BD-LSTM preset");
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 4;
    cfg.train.checkpoint_every = steps;
    cfg.train.valid_every = steps;
    cfg
}

/// The flex CPU device in f32.
pub fn cpu() -> Device {
    any4d_train::backend::device(
        any4d_train::backend::Backend::Flex,
        any4d_train::backend::Precision::F32,
    )
    .expect("flex device")
}
