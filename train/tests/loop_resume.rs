//! The generic training loop on a toy MLP regression (issue 5 item 2 tests): resume equality (2n straight vs
//! n + Ctrl-C + resume + n, bitwise on the CPU backend), the NaN guard keeps the last good checkpoint, a
//! half-written checkpoint (kill -9) is ignored, the loss goes down and the plot is written.

use std::cell::Cell;
use std::path::Path;
use std::sync::Mutex;

use any4d_train::backend::{Backend, Precision, device};
use any4d_train::checkpoint;
use any4d_train::config::{Duration, OptimConfig, TrainConfig};
use any4d_train::loop_common::{LoopSetup, Losses, Objective, Outcome, StopFlag, train};
use any4d_train::progress::ProgressMode;
use any4d_train::run_folder::{METRICS_FILE, PLOT_FILE, RunFolder, VALID_FILE, read_table};
use any4d_train::{Result, TrainError};
use burn::module::{Module, ModuleVisitor, Param};
use burn::nn::{Linear, LinearConfig, Relu};
use burn::prelude::{Device, Tensor, TensorData};
use burn::tensor::Distribution;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// burn's CPU RNG seed is process-wide: tests that train run one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

#[derive(Module, Debug)]
struct Mlp {
    fc1: Linear,
    fc2: Linear,
    act: Relu,
}

impl Mlp {
    fn new(device: &Device) -> Self {
        device.seed(1);
        Mlp {
            fc1: LinearConfig::new(4, 16).init(device),
            fc2: LinearConfig::new(16, 1).init(device),
            act: Relu::new(),
        }
    }
    fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.fc2.forward(self.act.forward(self.fc1.forward(x)))
    }
}

/// y = Σx / 2 on 40 fixed examples; the host RNG adds input jitter and the device RNG target noise, so both
/// random streams must be restored for an exact resume.
struct Toy {
    xs: Vec<[f32; 4]>,
    stop_after_calls: Option<(usize, StopFlag)>,
    nan_at_call: Option<usize>,
    calls: Cell<usize>,
}

impl Toy {
    fn new() -> Self {
        let xs = (0..40).map(|i| {
            let f = i as f32;
            [(f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin(), (f * 1.3).cos()]
        });
        Toy {
            xs: xs.collect(),
            stop_after_calls: None,
            nan_at_call: None,
            calls: Cell::new(0),
        }
    }
}

impl Objective for Toy {
    type Model = Mlp;
    fn terms(&self) -> Vec<String> {
        vec!["mse".into()]
    }
    fn train_len(&self) -> usize {
        32
    }
    fn loss(&self, model: &Mlp, idx: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let calls = self.calls.get() + 1;
        self.calls.set(calls);
        if let Some((n, flag)) = &self.stop_after_calls
            && calls == *n
        {
            flag.request();
        }
        let mut flat = Vec::new();
        for &i in idx {
            flat.extend(self.xs[i].iter().map(|v| v + rng.random_range(-0.01f32..0.01)));
        }
        let x = Tensor::<2>::from_data(TensorData::new(flat, [idx.len(), 4]), device);
        let noise = Tensor::<2>::random([idx.len(), 1], Distribution::Normal(0.0, 0.01), device);
        let y = x.clone().sum_dim(1).div_scalar(2.0) + noise;
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
        let flat: Vec<f32> = self.xs[32..].iter().flatten().copied().collect();
        let x = Tensor::<2>::from_data(TensorData::new(flat, [8, 4]), device);
        let y = x.clone().sum_dim(1).div_scalar(2.0);
        let mse = f64::from((model.forward(x) - y).square().mean().into_scalar::<f32>());
        Ok(Some(vec![mse, mse]))
    }
}

fn cfgs(steps: u64) -> (TrainConfig, OptimConfig) {
    let train = TrainConfig {
        seed: 666,
        duration: Duration::Steps(steps),
        batch_size: 8,
        micro_batch: 4,
        checkpoint_every: 3,
        keep_last: 2,
        valid_every: 4,
        progress_every_secs: 5.0,
    };
    let optim = OptimConfig {
        lr: 1e-2,
        beta1: 0.9,
        beta2: 0.99,
        weight_decay: 0.01,
        eps: 1e-8,
        grad_clip: 1.0,
    };
    (train, optim)
}

fn run_loop(toy: &Toy, run: &RunFolder, steps: u64, stop: StopFlag, resume: Option<&Path>) -> Result<(Mlp, Outcome)> {
    let (train_cfg, optim_cfg) = cfgs(steps);
    let dev = device(Backend::Flex, Precision::F32)?.autodiff();
    let setup = LoopSetup {
        run,
        train: &train_cfg,
        optim: &optim_cfg,
        device: dev.clone(),
        stop,
        progress: ProgressMode::Quiet,
        resume: resume.map(Path::to_path_buf),
    };
    train(toy, Mlp::new(&dev), setup)
}

fn params(m: &Mlp) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0.extend(p.val().into_data().try_to_vec::<f32>().unwrap());
        }
    }
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

fn new_run(dir: &Path, name: &str) -> RunFolder {
    RunFolder::create(dir, name, "# toy\n", &["mse"]).unwrap()
}

#[test]
fn resume_after_ctrl_c_equals_training_straight_through() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let n = 5;
    let straight_run = new_run(dir.path(), "straight");
    let (straight, outcome) = run_loop(&Toy::new(), &straight_run, 2 * n, StopFlag::new(), None).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 10, .. }), "{outcome:?}");

    // Ctrl-C during step n (2 micro-batches per step): the loop finishes step n, saves and returns.
    let stop = StopFlag::new();
    let mut toy = Toy::new();
    toy.stop_after_calls = Some((2 * n as usize, stop.clone()));
    let split_run = new_run(dir.path(), "split");
    let (_, outcome) = run_loop(&toy, &split_run, 2 * n, stop, None).unwrap();
    let Outcome::Interrupted { step, checkpoint } = outcome else {
        panic!("not interrupted: {outcome:?}")
    };
    assert_eq!(step, n);
    let (resumed, outcome) = run_loop(&Toy::new(), &split_run, 2 * n, StopFlag::new(), Some(&checkpoint)).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 10, .. }), "{outcome:?}");
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed parameters differ from straight training"
    );

    // The loss went down, metrics and the plot are there, old checkpoints were pruned.
    let t = read_table(&straight_run.path(METRICS_FILE)).unwrap();
    assert_eq!(t.rows.len(), 10);
    let v = read_table(&straight_run.path(VALID_FILE)).unwrap();
    assert!(
        v.rows.last().unwrap().1[1] < v.rows[0].1[1],
        "validation loss did not drop: {:?}",
        v.rows
    );
    assert!(straight_run.path(PLOT_FILE).is_file());
    let kept: Vec<u64> = checkpoint::list(&straight_run.path("checkpoints"))
        .unwrap()
        .iter()
        .map(|c| c.0)
        .collect();
    assert!(kept.len() <= 3 && kept.contains(&10), "{kept:?}");
}

#[test]
fn nan_loss_stops_with_a_message_and_keeps_the_last_good_checkpoint() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let run = new_run(dir.path(), "nan");
    let mut toy = Toy::new();
    toy.nan_at_call = Some(2 * 4 + 1); // first micro-batch of step 5; checkpoints at 3 (and 4: best valid)
    let err = run_loop(&toy, &run, 10, StopFlag::new(), None).unwrap_err();
    let TrainError::NonFinite { step, last_good, .. } = &err else {
        panic!("wrong error: {err}")
    };
    assert_eq!(*step, 5);
    let good = last_good.clone().expect("a checkpoint existed");
    assert!(good.ends_with("step_4"), "{}", good.display());
    assert!(err.to_string().contains("non-finite loss term `mse`"), "{err}");
    assert!(checkpoint::read_state(&good).unwrap().step == 4);
    assert!(checkpoint::load_model(Mlp::new(&Device::flex()), &good).is_ok());
}

#[test]
fn a_half_written_checkpoint_is_ignored_on_resume() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let run = new_run(dir.path(), "killed");
    let stop = StopFlag::new();
    let mut toy = Toy::new();
    toy.stop_after_calls = Some((6, stop.clone()));
    run_loop(&toy, &run, 8, stop, None).unwrap();
    // What kill -9 during a save leaves: a temporary folder without state.json.
    let ckpts = run.path("checkpoints");
    std::fs::create_dir(ckpts.join(".tmp_step_6")).unwrap();
    std::fs::write(ckpts.join(".tmp_step_6").join("model.bpk"), b"torn").unwrap();
    let latest = checkpoint::latest(&ckpts).unwrap().unwrap();
    assert!(latest.ends_with("step_3"), "{}", latest.display());
    let (_, outcome) = run_loop(&Toy::new(), &run, 8, StopFlag::new(), Some(&latest)).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 8, .. }), "{outcome:?}");
}
