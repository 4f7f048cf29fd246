//! Data-parallel training (`any4d_train::multi_device`): on a deterministic toy regression,
//! two CPU worker devices give the parameters of the single-device loop with the same global batch (within
//! float-summation tolerance); a tiny VAE trains over `flex,flex` with the losses of one device; the RF's latent
//! cache encoded on two CPU workers is one worker's; `--devices` parsing rejects bad entries with a message naming
//! them.

mod common;

use any4d_train::backend::{Backend, Precision, device};
use any4d_train::config::{OptimConfig, TrainConfig};
use any4d_train::devices::{DeviceSpec, Parallel, Strategy};
use any4d_train::loop_common::{Outcome, RunOptions, StopFlag, train};
use any4d_train::multi_device::train_data_parallel;
use any4d_train::progress::ProgressMode;
use any4d_train::rf_loop::{encode_latents, encode_latents_on_workers};
use any4d_train::run_folder::{METRICS_FILE, RunFolder, read_table};
use any4d_train::runs::load_vae_run;
use any4d_train::vae_loop::{LATENT_STATS_FILE, train_vae};
use burn::prelude::Device;
use common::{Mlp, Toy, params, quiet_setup, serial, synth_store, tiny_vae, toy_configs, vae_fixture};

/// The toy loop's configs with micro-batches of 2 and no checkpoint or validation before the end.
fn cfgs(steps: u64) -> (TrainConfig, OptimConfig) {
    let (train, optim) = toy_configs(steps);
    let train = TrainConfig {
        micro_batch: 2,
        checkpoint_every: 100,
        keep_last: 1,
        valid_every: 100,
        ..train
    };
    (train, optim)
}

/// Single device vs `workers` (autodiff devices): max |Δθ| after `steps` steps and the data-parallel losses.
fn compare(workers: &[Device], steps: u64) -> (f32, Vec<f64>) {
    let dir = tempfile::tempdir().unwrap();
    let toy = Toy::exact();
    let (train_cfg, optim_cfg) = cfgs(steps);
    let dev = device(Backend::Flex, Precision::F32).unwrap().autodiff();
    let run1 = RunFolder::create(dir.path(), "one", "# toy\n", &["mse"]).unwrap();
    let (one, _) = train(
        &toy,
        Mlp::new(&dev),
        quiet_setup(&run1, &train_cfg, &optim_cfg, dev.clone(), None),
    )
    .unwrap();
    let run2 = RunFolder::create(dir.path(), "many", "# toy\n", &["mse"]).unwrap();
    let (many, outcome) = train_data_parallel(
        &toy,
        Mlp::new(&dev),
        quiet_setup(&run2, &train_cfg, &optim_cfg, dev.clone(), None),
        workers,
        Strategy::MainDevice,
    )
    .unwrap();
    assert!(
        matches!(outcome, Outcome::Finished { steps: s, .. } if s == steps),
        "{outcome:?}"
    );
    let (a, b) = (params(&one), params(&many));
    assert_eq!(a.len(), b.len());
    let diff = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    (diff, column(&run2, "loss"))
}

/// One column of `metrics.csv`, by name.
fn column(run: &RunFolder, name: &str) -> Vec<f64> {
    let table = read_table(&run.path(METRICS_FILE)).unwrap();
    // `header` starts with `step`, which `rows` keep apart.
    let i = table.header.iter().position(|c| c == name).unwrap() - 1;
    table.rows.iter().map(|(_, r)| r[i]).collect()
}

#[test]
fn two_cpu_workers_match_one_device_with_the_same_global_batch() {
    let _g = serial();
    let flex = device(Backend::Flex, Precision::F32).unwrap().autodiff();
    let (diff, losses) = compare(&[flex.clone(), flex], 10);
    eprintln!("flex,flex: max |Δθ| = {diff:e}, losses {losses:?}");
    assert!(diff < 1e-5, "max parameter difference {diff}");
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
    assert!(losses.last().unwrap() < &losses[0], "loss did not fall: {losses:?}");
}

#[test]
fn flex_and_ndarray_as_two_devices_match_one_device() {
    let _g = serial();
    let flex = device(Backend::Flex, Precision::F32).unwrap().autodiff();
    let nd = device(Backend::Ndarray, Precision::F32).unwrap().autodiff();
    let (diff, _) = compare(&[flex, nd], 5);
    eprintln!("flex,ndarray: max |Δθ| = {diff:e}");
    assert!(diff < 1e-4, "max parameter difference {diff}");
}

#[test]
fn tiny_vae_over_two_cpu_workers_trains_the_numbers_of_one_device() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let store = synth_store(dir.path(), 1);
    let mut cfg = tiny_vae(4);
    cfg.train.micro_batch = 2;
    cfg.train.checkpoint_every = 4;
    cfg.train.valid_every = 4;
    let run = |name: &str, devices: Option<&str>| {
        let parallel = devices.map(|d| Parallel::parse(d, Strategy::Auto).unwrap());
        if let Some(p) = &parallel {
            assert_eq!(p.strategy, Strategy::MainDevice);
        }
        let opts = RunOptions {
            data: store.clone(),
            runs_dir: dir.path().join("runs"),
            name: name.into(),
            progress: ProgressMode::Quiet,
            stop: StopFlag::new(),
            parallel,
        };
        train_vae(&cfg, &opts).expect("VAE run")
    };
    let (two, outcome) = run("two", Some("flex,flex"));
    assert!(matches!(outcome, Outcome::Finished { steps: 4, .. }), "{outcome:?}");
    assert!(two.path(LATENT_STATS_FILE).is_file(), "no latent statistics written");
    let (one, _) = run("one", None);
    for col in ["rec", "kl", "loss"] {
        let (a, b) = (column(&one, col), column(&two, col));
        assert_eq!(b.len(), 4, "{col}");
        assert!(b.iter().all(|v| v.is_finite()), "{col} not finite: {b:?}");
        // The posterior noise comes from each micro-batch's own generator: the two workers draw what one device
        // draws, whichever thread reaches the backend first (differences are float summation order only).
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x - y).abs() <= 1e-5 * x.abs().max(1e-3),
                "{col}: one device {a:?}, two workers {b:?}"
            );
        }
    }
}

#[test]
fn latents_encoded_on_two_workers_are_one_workers() {
    let _g = serial();
    let f = vae_fixture(2);
    let dev = device(Backend::Flex, Precision::F32).unwrap();
    let vae = load_vae_run(&f.vae_run, &dev).unwrap();
    let store = any4d_data::store::Store::open(&f.store).unwrap();
    let all: Vec<usize> = (0..store.len()).collect();
    assert!(all.len() > 6, "the fixture store holds {} clips", all.len());
    let one = encode_latents(&vae.model, &store, &all, 3, vae.tokens(), &dev).unwrap();
    // Two workers over every clip, and more workers than micro-batches over two clips.
    for (indices, workers) in [(&all[..], 2), (&all[..2], 4)] {
        let got = encode_latents_on_workers(&vae.model, &store, indices, 3, vae.tokens(), &dev, workers, None).unwrap();
        assert_eq!(
            (got.frames, got.tokens, got.channels),
            (one.frames, one.tokens, one.channels)
        );
        assert_eq!(got.clips.len(), indices.len());
        for (a, b) in one.clips.iter().zip(&got.clips) {
            assert_eq!((a.store_index, &a.caption), (b.store_index, &b.caption));
            assert_eq!(
                (&a.z0, &a.mu, &a.logvar),
                (&b.z0, &b.mu, &b.logvar),
                "clip {}",
                a.store_index
            );
        }
    }
}

#[test]
fn device_lists_parse_and_bad_entries_are_named() {
    let specs = DeviceSpec::parse_list("flex, ndarray").unwrap();
    assert_eq!(specs.len(), 2);
    assert_eq!(specs[1].backend, Backend::Ndarray);
    let cuda = DeviceSpec::parse("cuda:3").unwrap();
    assert_eq!((cuda.backend, cuda.index), (Backend::Cuda, 3));
    let e = DeviceSpec::parse_list("flex,tpu").unwrap_err().to_string();
    assert!(e.contains("`tpu`"), "{e}");
    let e = DeviceSpec::parse("flex:1").unwrap_err().to_string();
    assert!(e.contains("one device"), "{e}");
    let e = DeviceSpec::parse("cuda:x").unwrap_err().to_string();
    assert!(e.contains("`x`"), "{e}");
    assert!(DeviceSpec::parse_list(",").is_err());
}

#[test]
fn strategies_resolve_and_ddp_is_refused_where_burn_has_no_all_reduce() {
    let resolve = |d: &str, s: Strategy| Parallel::parse(d, s).map(|p| p.strategy);
    assert_eq!(resolve("cuda:0,cuda:1", Strategy::Auto).unwrap(), Strategy::Ddp);
    assert_eq!(
        resolve("cuda:0,cuda:1", Strategy::MainDevice).unwrap(),
        Strategy::MainDevice
    );
    assert_eq!(resolve("cuda:0", Strategy::Auto).unwrap(), Strategy::MainDevice);
    assert_eq!(resolve("cuda:0,cuda:0", Strategy::Auto).unwrap(), Strategy::MainDevice);
    assert_eq!(resolve("flex,flex", Strategy::Auto).unwrap(), Strategy::MainDevice);
    for devices in ["flex,flex", "vulkan:0,vulkan:1", "cuda:0,flex"] {
        let e = resolve(devices, Strategy::Ddp).unwrap_err().to_string();
        assert!(
            e.contains("needs cuda devices") && e.contains("main-device"),
            "{devices}: {e}"
        );
    }
    let e = resolve("cuda:1,cuda:1", Strategy::Ddp).unwrap_err().to_string();
    assert!(e.contains("listed once"), "{e}");
}
