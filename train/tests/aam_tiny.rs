//! The AnimateAnyMesh reference (docs/method.md §5.5) end to end at the tiny size: a sequence-wise VAE run, an RF
//! on its latents (`configs/rf/aam_tiny.toml`: one trajectory slot, no keyframes) that lowers its loss and logs
//! validation samples, and the `aam` evaluation row built from the run folder, which reads the reference frame
//! only. Runs given to the wrong flag, configs on the wrong VAE kind and stores of the wrong clip length are
//! refused with errors that say so, before a run folder is claimed.

mod common;

use std::path::PathBuf;
use std::sync::OnceLock;

use any4d_data::store::{Split, Store};
use any4d_eval::methods::{MethodKind, hide_non_keyframes};
use any4d_train::config::Duration;
use any4d_train::evaluate::{LearnedRuns, SamplingSetup, build_methods};
use any4d_train::loop_common::Outcome;
use any4d_train::rf_loop::{LatentDraw, RfRunConfig, RfRunOptions, train_rf};
use any4d_train::run_folder::{METRICS_FILE, SAMPLES_FILE, read_table};
use any4d_train::vae_loop::train_vae;
use common::{VaeFixture, cpu, root, run_options, serial, synth_store, tiny_dymesh_vae, vae_fixture, vae_fixture_with};

/// The 4-frame store (seed 1) and a 6-step sequence-wise VAE run on it.
fn dymesh() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture_with(1, tiny_dymesh_vae(6)))
}

/// The same store with a frame-wise VAE run, for the wrong-kind errors.
fn framewise() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture(1))
}

/// configs/rf/aam_tiny.toml for `steps` steps of 4 clips on the fixture, validation samples of 2 clips at the end.
fn aam_tiny(steps: u64) -> RfRunConfig {
    let mut cfg = RfRunConfig::load(&root().join("configs/rf/aam_tiny.toml"), &[]).expect("configs/rf/aam_tiny.toml");
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 4;
    cfg.train.checkpoint_every = steps;
    cfg.train.valid_every = steps;
    cfg.rf.valid_sample_every = steps;
    cfg.rf.valid_sample_clips = 2;
    cfg.rf.valid_sample_grid = 4;
    // As in the keyframe RF's test: the 6-step VAE's posterior σ dwarfs μ; its means are learnable.
    cfg.rf.latent = LatentDraw::Mean;
    cfg
}

fn opts(f: &VaeFixture, name: &str) -> RfRunOptions {
    RfRunOptions {
        run: run_options(&f.store, &f.dir, name),
        vae_run: Some(f.vae_run.clone()),
        init: None,
        latents: None,
    }
}

const STEPS: u64 = 60;

fn trained_aam() -> &'static PathBuf {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let (run, outcome) = train_rf(&aam_tiny(STEPS), &opts(dymesh(), "aam")).expect("tiny AAM run");
        assert!(matches!(outcome, Outcome::Finished { steps: STEPS, .. }), "{outcome:?}");
        run.root().to_path_buf()
    })
}

#[test]
fn tiny_aam_run_lowers_its_loss_and_logs_validation_samples() {
    let _g = serial();
    let run = trained_aam();
    let t = read_table(&run.join(METRICS_FILE)).unwrap();
    let loss = t.header.iter().position(|h| h == "loss").unwrap() - 1;
    let kf = t.header.iter().position(|h| h == "kf_frac").unwrap() - 1;
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[loss]).sum::<f64>() / rows.len() as f64;
    let n = t.rows.len();
    assert_eq!(n as u64, STEPS);
    let (first, last) = (mean(&t.rows[..10]), mean(&t.rows[n - 10..]));
    assert!(last < 0.8 * first, "AAM loss did not drop: {first} → {last}");
    assert!(
        t.rows.iter().all(|r| r.1[kf] == 0.0),
        "the reference is trained without keyframes"
    );
    let samples = read_table(&run.join(SAMPLES_FILE)).unwrap();
    let (step, scores) = samples.rows.last().expect("a validation-sample row");
    assert_eq!(*step, STEPS);
    assert!(scores.iter().all(|v| v.is_finite() && *v >= 0.0), "{scores:?}");
}

#[test]
fn the_aam_row_reads_only_the_reference_frame_and_the_caption() {
    let _g = serial();
    let run = trained_aam();
    let dev = cpu();
    let runs = LearnedRuns {
        aam: Some(run.clone()),
        ..LearnedRuns::default()
    };
    let built = build_methods(&[MethodKind::Aam], &runs, SamplingSetup::default(), &dev).unwrap();
    assert!(
        built.checkpoints[0].1.contains(&format!("step {STEPS}")),
        "{:?}",
        built.checkpoints
    );
    let method = &built.methods[0];
    assert_eq!(method.kind(), MethodKind::Aam);
    let store = Store::open(&dymesh().store).unwrap();
    let gt = store.get(store.indices(Split::Val)[0]).unwrap().clip;
    let keys = [0, 3];
    let visible = hide_non_keyframes(&gt, &keys);
    let a = method.complete(&visible, &keys, &gt.caption, 7).unwrap();
    assert_eq!(a.len(), gt.frames * gt.n_vertices);
    assert!(a.iter().flatten().all(|v| v.is_finite()));
    assert_eq!(
        a,
        method.complete(&visible, &keys, &gt.caption, 7).unwrap(),
        "same seed, same output"
    );
    assert_ne!(
        a,
        method.complete(&visible, &keys, &gt.caption, 8).unwrap(),
        "the seed reaches the noise"
    );
    // Keyframes other than the reference do not reach the network: the full clip or other keyframes give the same.
    assert_eq!(a, method.complete(&gt, &[0, 1, 2, 3], &gt.caption, 7).unwrap());
    let mut moved = gt.clone();
    for v in &mut moved.vertices[gt.n_vertices..] {
        v[0] += 0.5;
    }
    assert_eq!(a, method.complete(&moved, &keys, &gt.caption, 7).unwrap());
    assert_ne!(
        a,
        method.complete(&visible, &keys, "", 7).unwrap(),
        "the caption reaches the network"
    );
}

#[test]
fn runs_given_to_the_wrong_flag_and_configs_on_the_wrong_vae_are_refused() {
    let _g = serial();
    let run = trained_aam();
    let dev = cpu();
    // The AAM run as ours or as the Baseline.
    for (kind, runs) in [
        (
            MethodKind::KeyframeRf,
            LearnedRuns {
                rf: Some(run.clone()),
                ..LearnedRuns::default()
            },
        ),
        (
            MethodKind::ReplacementRf,
            LearnedRuns {
                baseline_rf: Some(run.clone()),
                ..LearnedRuns::default()
            },
        ),
    ] {
        let e = build_methods(&[kind], &runs, SamplingSetup::default(), &dev)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("AnimateAnyMesh reference") && e.contains("`aam`"), "{e}");
    }
    // The shipped Baseline (an RF on a frame-wise VAE) as the AAM reference.
    let runs = LearnedRuns {
        aam: Some(root().join("weights/small/baseline-rf")),
        ..LearnedRuns::default()
    };
    let e = build_methods(&[MethodKind::Aam], &runs, SamplingSetup::default(), &dev)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("sequence-wise VAE") && e.contains("frame-wise"), "{e}");
    let e = build_methods(
        &[MethodKind::Aam],
        &LearnedRuns::default(),
        SamplingSetup::default(),
        &dev,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("--aam"), "{e}");

    // The AAM config on a frame-wise VAE, and ours on the sequence-wise VAE: refused, no run folder.
    let e = train_rf(&aam_tiny(2), &opts(framewise(), "aam-on-framewise"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("needs a sequence-wise VAE run"), "{e}");
    assert!(!framewise().dir.join("runs/aam-on-framewise-1").exists());
    let mut ours = RfRunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).unwrap();
    (ours.model.frames, ours.model.channels, ours.rf.k_max) = (4, 16, 3);
    let e = train_rf(&ours, &opts(dymesh(), "ours-on-dymesh"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("model.frames = 1") && e.contains("\"none\""), "{e}");
    assert!(!dymesh().dir.join("runs/ours-on-dymesh-1").exists());
    // The AAM config told the scene: its one trajectory slot has no frames for the scene's features.
    let mut scened = aam_tiny(2);
    scened.model.scene.global = true;
    let e = train_rf(&scened, &opts(dymesh(), "aam-scene"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("sequence-wise") && e.contains("model.scene.global"), "{e}");
    assert!(!dymesh().dir.join("runs/aam-scene-1").exists());
}

#[test]
fn a_sequence_wise_vae_refuses_clips_of_another_length() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let store = synth_store(dir.path(), 2); // 4-frame clips
    let mut cfg = tiny_dymesh_vae(2);
    cfg.train.micro_batch = 4;
    if let any4d_model::any_vae::AnyMeshVaeConfig::Sequencewise(m) = &mut cfg.model {
        m.frames = 16;
    }
    let opts = run_options(&store, dir.path(), "long");
    let e = train_vae(&cfg, &opts).err().unwrap().to_string();
    assert!(e.contains("model.frames = 16") && e.contains("4-frame clips"), "{e}");
    assert!(!dir.path().join("runs").join("long-1").exists());
}
