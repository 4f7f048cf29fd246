//! The BD-LSTM loop (latent adaptation, docs/method.md §5.3) on a tiny frozen VAE: a short run lowers (B3),
//! validation is deterministic and reproduced by the loaded run, the run completes clips as the `bdlstm` row, resume is bitwise equal to straight training, and
//! bad configs or a missing VAE give errors naming the field.

mod common;

use std::path::PathBuf;
use std::sync::OnceLock;

use any4d_eval::methods::{MethodKind, hide_non_keyframes};
use any4d_train::bdlstm::train_bdlstm;
use any4d_train::bdlstm_loop::{BDLSTM_TERMS, BdlstmObjective, BdlstmRunConfig, BdlstmRunOptions, load_bdlstm_run};
use any4d_train::config::{Duration, Override};
use any4d_train::evaluate::{LearnedRuns, SamplingSetup, build_methods};
use any4d_train::loop_common::{Objective, Outcome, train};
use any4d_train::pack::{Precision as PackPrecision, pack_run};
use any4d_train::run_config::RunConfig;
use any4d_train::run_folder::{METRICS_FILE, RunFolder, VALID_FILE, read_table};
use any4d_train::runs::load_vae_run;
use common::{VaeFixture, bdlstm_preset, cpu, params, quiet_setup, root, run_options, serial, vae_fixture};

/// The shared store and tiny VAE run (seed 4), made once per test process.
fn fixture() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture(4))
}

fn opts(name: &str) -> BdlstmRunOptions {
    let f = fixture();
    BdlstmRunOptions {
        run: run_options(&f.store, &f.dir, name),
        vae_run: Some(f.vae_run.clone()),
    }
}

/// configs/bdlstm/tiny.toml for `steps` steps of 4 clips.
fn tiny(steps: u64) -> BdlstmRunConfig {
    bdlstm_preset("tiny.toml", steps)
}

#[test]
fn tiny_bdlstm_lowers_its_loss_and_its_run_loads() {
    let _g = serial();
    let steps = 80;
    let cfg = tiny(steps);
    let (run, outcome) = train_bdlstm(&cfg, &opts("bd")).expect("tiny BD-LSTM run");
    assert!(matches!(outcome, Outcome::Finished { steps: 80, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    assert_eq!(t.rows.len(), steps as usize);
    let total = BDLSTM_TERMS.len(); // the `loss` column follows the terms
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[total]).sum::<f64>() / rows.len() as f64;
    let (first, last) = (mean(&t.rows[..10]), mean(&t.rows[t.rows.len() - 10..]));
    assert!(last < 0.8 * first, "loss {first} → {last}");

    // The loaded run reproduces the logged validation (posterior means, fixed seed).
    let dev = cpu();
    let loaded = load_bdlstm_run(run.root(), &dev).unwrap();
    assert_eq!(loaded.config, cfg);
    assert_eq!(loaded.step, steps);
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    let objective = BdlstmObjective::new(&cfg, &fixture().store, &vae, &dev).unwrap();
    let values = objective
        .validate(&loaded.model, &dev, steps)
        .unwrap()
        .expect("VAL clips");
    let logged = read_table(&run.path(VALID_FILE)).unwrap();
    let (step, row) = logged.rows.last().unwrap();
    assert_eq!(*step, steps);
    for (v, l) in values.iter().zip(row) {
        assert!(
            (v - l).abs() <= 1e-5 * l.abs().max(1.0),
            "validation {values:?} vs logged {row:?}"
        );
    }
    // As an evaluation row: every frame decoded and finite, the same output for the same seed, keyframes
    // required at both ends, and a clear error without the run.
    let runs = LearnedRuns {
        bdlstm: Some(run.root().to_path_buf()),
        ..LearnedRuns::default()
    };
    let built = build_methods(&[MethodKind::Bdlstm], &runs, SamplingSetup::default(), &dev).unwrap();
    assert!(
        built.checkpoints[0].1.contains(&format!("step {steps}")),
        "{:?}",
        built.checkpoints
    );
    let method = &built.methods[0];
    let store = any4d_data::store::Store::open(&fixture().store).unwrap();
    let clip = store.get(store.indices(any4d_data::store::Split::Val)[0]).unwrap().clip;
    let keys = [0, 3];
    let visible = hide_non_keyframes(&clip, &keys);
    let a = method.complete(&visible, &keys, "", 7).unwrap();
    assert_eq!(a.len(), clip.frames * clip.n_vertices);
    assert!(a.iter().flatten().all(|v| v.is_finite()));
    assert_eq!(a, method.complete(&visible, &keys, "", 7).unwrap());
    let err = method.complete(&visible, &[0, 2], "", 7).unwrap_err().to_string();
    assert!(err.contains("must be keyframes"), "{err}");
    // Its keyframe-corrected row (docs/method.md §5.6) is built on the same run and reproduces the given keyframes.
    let kind = MethodKind::parse("bdlstm_corrected").unwrap();
    let corrected = build_methods(&[kind], &runs, SamplingSetup::default(), &dev).unwrap();
    assert_eq!(
        corrected.checkpoints,
        vec![(kind.label(), built.checkpoints[0].1.clone())]
    );
    let c = corrected.methods[0].complete(&visible, &keys, "", 7).unwrap();
    let n = clip.n_vertices;
    for k in keys {
        let off = c[k * n..(k + 1) * n]
            .iter()
            .flatten()
            .zip(visible.frame(k).iter().flatten())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(off < 1e-5, "corrected keyframe {k} off by {off}");
    }
    assert_ne!(c, a, "the raw row's keyframes are decoded, not given");
    let err = build_methods(
        &[MethodKind::Bdlstm],
        &LearnedRuns::default(),
        SamplingSetup::default(),
        &dev,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("--bdlstm"), "{err}");
    // An RF or VAE folder is not a BD-LSTM run.
    let err = load_bdlstm_run(&fixture().vae_run, &dev).err().unwrap().to_string();
    assert!(err.contains("not a BD-LSTM run"), "{err}");
    // `model pack` keeps a BD-LSTM run a BD-LSTM run: it loads with the same parameters and completes the same.
    let out = tempfile::tempdir().unwrap();
    let packed = pack_run(run.root(), &out.path().join("bd"), PackPrecision::Full, None, &dev).unwrap();
    assert_eq!((packed.kind, packed.step), ("BD-LSTM", steps));
    let reloaded = load_bdlstm_run(&out.path().join("bd"), &dev).unwrap();
    assert_eq!(params(&reloaded.model), params(&loaded.model));
    let runs = LearnedRuns {
        bdlstm: Some(out.path().join("bd")),
        ..LearnedRuns::default()
    };
    let built = build_methods(&[MethodKind::Bdlstm], &runs, SamplingSetup::default(), &dev).unwrap();
    assert_eq!(a, built.methods[0].complete(&visible, &keys, "", 7).unwrap());
}

#[test]
fn tiny_bdlstm_resume_is_bitwise_equal_to_straight_training() {
    let _g = serial();
    let dev = cpu();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    let cfg = tiny(6);
    let objective = BdlstmObjective::new(&cfg, &fixture().store, &vae, &dev).unwrap();
    let go = |run: &RunFolder, steps: u64, resume: Option<PathBuf>| {
        let mut cfg = cfg.clone();
        cfg.train.duration = Duration::Steps(steps);
        cfg.train.checkpoint_every = 3;
        cfg.train.valid_every = 3;
        let ad = dev.clone().autodiff();
        ad.seed(cfg.train.seed);
        let model = cfg.init(vae.tokens(), vae.latent_channels(), &ad);
        train(&objective, model, quiet_setup(run, &cfg.train, &cfg.optim, ad, resume)).unwrap()
    };
    let runs = fixture().dir.join("resume-runs");
    let straight_run = RunFolder::create(&runs, "straight", "", &BDLSTM_TERMS).unwrap();
    let (straight, _) = go(&straight_run, 6, None);
    let split_run = RunFolder::create(&runs, "split", "", &BDLSTM_TERMS).unwrap();
    let (_, first) = go(&split_run, 3, None);
    let Outcome::Finished { checkpoint, .. } = first else {
        panic!("{first:?}")
    };
    let (resumed, _) = go(&split_run, 6, Some(checkpoint));
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed BD-LSTM differs from straight training"
    );
}

#[test]
fn bad_bdlstm_configs_and_setups_name_the_field() {
    let _g = serial();
    let path = root().join("configs/bdlstm/tiny.toml");
    for (key, value, needle) in [
        ("bdlstm.min_window", "2", "bdlstm.min_window"),
        ("bdlstm.max_window", "3", "bdlstm.max_window"),
        ("model.latent", "0", "model.latent"),
        ("model.layers", "100000", "model.layers"),
        ("bdlstm.kl_weight", "-1.0", "bdlstm.kl_weight"),
        ("bdlstm.merge_threshold", "inf", "bdlstm.merge_threshold"),
        ("bdlstm.merge_tries", "0", "bdlstm.merge_tries"),
        ("bdlstm.latent", "\"median\"", "latent"),
    ] {
        let set: Override = format!("{key}={value}").parse().unwrap();
        let mut overrides = vec![set];
        if key == "bdlstm.max_window" {
            overrides.push("bdlstm.min_window=4".parse().unwrap());
        }
        let err = BdlstmRunConfig::load(&path, &overrides).unwrap_err().to_string();
        assert!(err.contains(needle), "{key} = {value}: {err}");
    }
    assert!(matches!(RunConfig::load(&path, &[]).unwrap(), RunConfig::Bdlstm(_)));

    let mut no_vae = opts("novae");
    no_vae.vae_run = None;
    let err = train_bdlstm(&tiny(1), &no_vae).err().unwrap().to_string();
    assert!(err.contains("--vae"), "{err}");
    // Windows longer than the store's 4-frame clips.
    let mut cfg = tiny(1);
    cfg.bdlstm.min_window = 5;
    let err = train_bdlstm(&cfg, &opts("long")).err().unwrap().to_string();
    assert!(err.contains("4-frame") && err.contains("min_window"), "{err}");
    assert!(
        !fixture().dir.join("runs/long-1").exists(),
        "a failed start claimed a run folder"
    );
}
