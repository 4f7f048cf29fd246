//! The generic training loop on a toy MLP regression: resume equality (2n straight vs
//! n + Ctrl-C + resume + n, bitwise on the CPU backend), the NaN guard keeps the last good checkpoint, a
//! half-written checkpoint (kill -9) is ignored, the loss goes down and the plot is written; the parameter
//! average (docs/method.md §4.8) follows its formula, resumes exactly and is what a finished run samples with.

mod common;

use std::path::Path;

use any4d_train::backend::{Backend, Precision, device};
use any4d_train::checkpoint;
use any4d_train::loop_common::{LoopSetup, Outcome, StopFlag, ema_decay_at, ema_update, train};
use any4d_train::run_folder::{METRICS_FILE, PLOT_FILE, RunFolder, VALID_FILE, read_table};
use any4d_train::{Result, TrainError};
use burn::module::Module;
use burn::prelude::Device;
use common::{Mlp, Toy, params, quiet_setup, serial, toy_configs};

fn run_loop(toy: &Toy, run: &RunFolder, steps: u64, stop: StopFlag, resume: Option<&Path>) -> Result<(Mlp, Outcome)> {
    run_averaged(toy, run, steps, 0.0, stop, resume)
}

fn run_averaged(
    toy: &Toy,
    run: &RunFolder,
    steps: u64,
    ema_decay: f64,
    stop: StopFlag,
    resume: Option<&Path>,
) -> Result<(Mlp, Outcome)> {
    let (mut train_cfg, optim_cfg) = toy_configs(steps);
    train_cfg.ema_decay = ema_decay;
    let dev = device(Backend::Flex, Precision::F32)?.autodiff();
    let setup = LoopSetup {
        stop,
        ..quiet_setup(run, &train_cfg, &optim_cfg, dev.clone(), resume.map(Path::to_path_buf))
    };
    train(toy, Mlp::new(&dev), setup)
}

fn new_run(dir: &Path, name: &str) -> RunFolder {
    RunFolder::create(dir, name, "# toy\n", &["mse"]).unwrap()
}

#[test]
fn resume_after_ctrl_c_equals_training_straight_through() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let n = 5;
    let straight_run = new_run(dir.path(), "straight");
    let (straight, outcome) = run_loop(&Toy::noisy(), &straight_run, 2 * n, StopFlag::new(), None).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 10, .. }), "{outcome:?}");

    // Ctrl-C during step n (2 micro-batches per step): the loop finishes step n, saves and returns.
    let stop = StopFlag::new();
    let mut toy = Toy::noisy();
    toy.stop_after_calls = Some((2 * n as usize, stop.clone()));
    let split_run = new_run(dir.path(), "split");
    let (_, outcome) = run_loop(&toy, &split_run, 2 * n, stop, None).unwrap();
    let Outcome::Interrupted { step, checkpoint } = outcome else {
        panic!("not interrupted: {outcome:?}")
    };
    assert_eq!(step, n);
    let (resumed, outcome) = run_loop(&Toy::noisy(), &split_run, 2 * n, StopFlag::new(), Some(&checkpoint)).unwrap();
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
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let run = new_run(dir.path(), "nan");
    let mut toy = Toy::noisy();
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
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let run = new_run(dir.path(), "killed");
    let stop = StopFlag::new();
    let mut toy = Toy::noisy();
    toy.stop_after_calls = Some((6, stop.clone()));
    run_loop(&toy, &run, 8, stop, None).unwrap();
    // What kill -9 during a save leaves: a temporary folder without state.json.
    let ckpts = run.path("checkpoints");
    std::fs::create_dir(ckpts.join(".tmp_step_6")).unwrap();
    std::fs::write(ckpts.join(".tmp_step_6").join("model.bpk"), b"torn").unwrap();
    let latest = checkpoint::latest(&ckpts).unwrap().unwrap();
    assert!(latest.ends_with("step_3"), "{}", latest.display());
    let (_, outcome) = run_loop(&Toy::noisy(), &run, 8, StopFlag::new(), Some(&latest)).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 8, .. }), "{outcome:?}");
}

#[test]
fn the_average_follows_its_formula() {
    // Mlp::new seeds and draws from burn's process-wide RNG: without the lock it races the other tests' draws.
    let _g = serial();
    let dev = Device::flex();
    let start = Mlp::new(&dev);
    let later = start.clone().map(&mut common::Shift(0.5));
    let avg = ema_update(start.clone(), &later, 0.9).unwrap();
    for ((a, s), l) in params(&avg).iter().zip(params(&start)).zip(params(&later)) {
        let want = 0.9 * s + 0.1 * l;
        assert!((a - want).abs() < 1e-6, "{a} vs {want}");
    }
    // A module whose parameters are not the model's (fresh ids) is refused, not silently left alone.
    let stranger = Mlp::new(&dev);
    let err = ema_update(stranger, &later, 0.9).unwrap_err();
    assert!(err.to_string().contains("without a partner"), "{err}");
    // The decay ramps up: step 1 keeps 2/11 of the start, step 10 000 the configured 0.999.
    assert!((ema_decay_at(0.999, 1) - 2.0 / 11.0).abs() < 1e-12);
    assert_eq!(ema_decay_at(0.999, 10_000), 0.999);
    assert_eq!(ema_decay_at(0.0, 5), 0.0);
}

#[test]
fn an_averaged_run_resumes_exactly_and_samples_with_the_average() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let n = 5;
    let straight_run = new_run(dir.path(), "straight");
    let (straight, _) = run_averaged(&Toy::noisy(), &straight_run, 2 * n, 0.9, StopFlag::new(), None).unwrap();

    let stop = StopFlag::new();
    let mut toy = Toy::noisy();
    toy.stop_after_calls = Some((2 * n as usize, stop.clone()));
    let split_run = new_run(dir.path(), "split");
    let (_, outcome) = run_averaged(&toy, &split_run, 2 * n, 0.9, stop, None).unwrap();
    let Outcome::Interrupted { checkpoint, .. } = outcome else {
        panic!("not interrupted: {outcome:?}")
    };
    assert!(checkpoint.join(checkpoint::EMA_FILE).is_file());
    let (resumed, outcome) = run_averaged(
        &Toy::noisy(),
        &split_run,
        2 * n,
        0.9,
        StopFlag::new(),
        Some(&checkpoint),
    )
    .unwrap();
    let Outcome::Finished { checkpoint: last, .. } = outcome else {
        panic!("not finished: {outcome:?}")
    };
    assert_eq!(params(&straight), params(&resumed), "resumed average differs");

    // The run returns and samples with the average; the trained parameters are a different point.
    let (sampled, averaged) = checkpoint::load_for_sampling(Mlp::new(&Device::flex()), &last).unwrap();
    assert!(averaged);
    assert_eq!(params(&sampled), params(&resumed));
    let trained = checkpoint::load_model(Mlp::new(&Device::flex()), &last).unwrap();
    assert_ne!(params(&trained), params(&sampled));

    // A run without the average has no ema.bpk and samples with the trained parameters; resuming a run whose
    // config asks for an average from such a checkpoint names the missing file.
    let plain_run = new_run(dir.path(), "plain");
    let (_, outcome) = run_loop(&Toy::noisy(), &plain_run, 3, StopFlag::new(), None).unwrap();
    let Outcome::Finished { checkpoint: plain, .. } = outcome else {
        panic!("not finished: {outcome:?}")
    };
    assert!(!plain.join(checkpoint::EMA_FILE).exists());
    assert!(
        !checkpoint::load_for_sampling(Mlp::new(&Device::flex()), &plain)
            .unwrap()
            .1
    );
    let err = run_averaged(&Toy::noisy(), &plain_run, 6, 0.9, StopFlag::new(), Some(&plain)).unwrap_err();
    assert!(err.to_string().contains("ema.bpk"), "{err}");
}
