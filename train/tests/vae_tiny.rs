//! A short tiny frame-wise VAE run on procedural clips lowers its loss, writes latent statistics, and resumes
//! exactly (n steps + resume + n steps = 2n steps straight, bitwise on the CPU backend, with training-time
//! augmentation on); a store of windows cut
//! from longer clips trains on one example per whole clip.

mod common;

use any4d_model::any_vae::AnyMeshVaeConfig;
use any4d_model::frame_vae::FrameVae;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::loop_common::{Outcome, RunOptions, StopFlag, train};
use any4d_train::progress::ProgressMode;
use any4d_train::run_folder::{METRICS_FILE, RunFolder, read_table};
use any4d_train::vae_loop::{LATENT_STATS_FILE, StoredLatentStats, VaeObjective, VaeRunConfig, train_vae};
use common::{params, quiet_setup, serial, sharded_synth_store, synth_store, tiny_vae};

fn tiny(steps: u64) -> VaeRunConfig {
    let mut cfg = tiny_vae(steps);
    cfg.train.micro_batch = 2;
    cfg.train.checkpoint_every = 5;
    cfg.train.valid_every = 5;
    cfg
}

#[test]
fn tiny_vae_run_lowers_its_loss_and_stores_latent_stats() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = synth_store(dir.path(), 3);
    let cfg = tiny(30);
    let opts = RunOptions {
        data,
        runs_dir: dir.path().join("runs"),
        name: "vae".into(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
        parallel: None,
    };
    let (run, outcome) = train_vae(&cfg, &opts).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 30, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    let loss = t.header.iter().position(|h| h == "loss").unwrap() - 1;
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[loss]).sum::<f64>() / rows.len() as f64;
    let (first, last) = (mean(&t.rows[..5]), mean(&t.rows[25..]));
    assert!(
        last < 0.8 * first,
        "loss did not drop: first 5 steps {first}, last 5 {last}"
    );
    let stats: StoredLatentStats =
        serde_json::from_str(&std::fs::read_to_string(run.path(LATENT_STATS_FILE)).unwrap()).unwrap();
    assert_eq!(stats.step, 30);
    assert!(stats.stats.motion_std > 0.0 && stats.stats.shape_std > 0.0, "{stats:?}");
    // Two frame-wise VAEs in one table 5 keep apart: the second row is `framewise_b`.
    let runs = any4d_train::evaluate::LearnedRuns {
        vae: Some(run.root().to_path_buf()),
        vae_b: Some(run.root().to_path_buf()),
        ..Default::default()
    };
    let dev = device(Backend::Flex, Precision::F32).unwrap();
    let (rows, ckpts) = any4d_train::evaluate::build_reconstructors(&runs, Default::default(), &dev).unwrap();
    let labels: Vec<String> = rows.iter().map(|r| r.label()).collect();
    assert_eq!(labels, ["framewise", "framewise_b"]);
    assert_eq!(
        ckpts.iter().map(|c| c.0.as_str()).collect::<Vec<_>>(),
        ["framewise", "framewise_b"]
    );
}

#[test]
fn windows_of_one_clip_are_one_training_example() {
    let dir = tempfile::tempdir().unwrap();
    let synth = any4d_data::synth::SynthConfig {
        clips: 6,
        seed: 4,
        frames: 7,
        min_vertices: 256,
        max_vertices: 512,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    let data = dir.path().join("windows");
    // 7-frame clips cut into 4-frame windows at stride 1: four windows per clip.
    any4d_data::store::write_synth_windows(&synth, &data, 32, 4, 1, None).unwrap();
    let store = any4d_data::store::Store::open(&data).unwrap();
    let train = store.indices(any4d_data::store::Split::Train);
    assert!(!train.is_empty() && train.len().is_multiple_of(4), "{}", train.len());
    let cfg = tiny(1);
    let objective = VaeObjective::<FrameVae>::new(&data, cfg.train.micro_batch, &cfg.vae).unwrap();
    use any4d_train::loop_common::Objective;
    assert_eq!(objective.train_len(), train.len() / 4, "an epoch visits each clip once");
    // Its loss runs on drawn windows.
    let dev = device(Backend::Flex, Precision::F32).unwrap().autodiff();
    let AnyMeshVaeConfig::Framewise(m) = &cfg.model else {
        panic!("tiny is frame-wise")
    };
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let l = objective.loss(&m.init(&dev), &[0, 1], &mut rng, &dev).unwrap();
    assert!(l.total.into_scalar::<f32>().is_finite());
}

/// `cfg`'s frame-wise VAE, freshly seeded, trained on the store `data` in `run` (resuming from `resume`).
fn train_framewise(
    data: &std::path::Path,
    cfg: &VaeRunConfig,
    run: &RunFolder,
    resume: Option<std::path::PathBuf>,
) -> any4d_train::error::Result<(FrameVae, Outcome)> {
    let AnyMeshVaeConfig::Framewise(m) = &cfg.model else {
        panic!("tiny is frame-wise")
    };
    let dev = device(Backend::Flex, Precision::F32).unwrap().autodiff();
    dev.seed(cfg.train.seed);
    let model = m.init(&dev);
    let objective = VaeObjective::<FrameVae>::new(data, cfg.train.micro_batch, &cfg.vae)?;
    train(&objective, model, quiet_setup(run, &cfg.train, &cfg.optim, dev, resume))
}

#[test]
fn tiny_vae_resume_is_bitwise_equal_to_straight_training() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = synth_store(dir.path(), 3);
    let n = 3;
    // With every augmentation on (docs/method.md §2.9): its draws come from the checkpointed generator.
    let augment = any4d_data::augment::Augment {
        yaw_degrees: 180.0,
        mirror: 0.5,
        scale: [0.8, 1.25],
        reverse: 0.5,
        speed: [0.5, 1.0],
        motion: [0.8, 1.5],
    };
    let go_with =
        |augment: &any4d_data::augment::Augment, run: &RunFolder, steps: u64, resume: Option<std::path::PathBuf>| {
            let mut cfg = tiny(steps);
            cfg.vae.augment = augment.clone();
            train_framewise(&data, &cfg, run, resume).unwrap()
        };
    let go = |run: &RunFolder, steps: u64, resume: Option<std::path::PathBuf>| go_with(&augment, run, steps, resume);
    let runs = dir.path().join("runs");
    let straight_run = RunFolder::create(&runs, "straight", "", &["rec", "kl"]).unwrap();
    let (straight, _) = go(&straight_run, 2 * n, None);
    let split_run = RunFolder::create(&runs, "split", "", &["rec", "kl"]).unwrap();
    let (_, first) = go(&split_run, n, None);
    let Outcome::Finished { checkpoint, .. } = first else {
        panic!("{first:?}")
    };
    let (resumed, _) = go(&split_run, 2 * n, Some(checkpoint));
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed VAE differs from straight training"
    );
    let plain_run = RunFolder::create(&runs, "plain", "", &["rec", "kl"]).unwrap();
    let (plain, _) = go_with(&Default::default(), &plain_run, 2 * n, None);
    assert_ne!(
        params(&plain),
        params(&straight),
        "the augmentation changed what the VAE saw"
    );
}

#[test]
fn a_sharded_store_streams_and_resumes_mid_epoch_across_shards_exactly() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = sharded_synth_store(dir.path(), 3, 3);
    let store = any4d_data::store::Store::open(&data).unwrap();
    assert_eq!((store.shard_count(), store.len()), (3, 10));
    let train_shards: std::collections::BTreeSet<usize> = store
        .indices(any4d_data::store::Split::Train)
        .into_iter()
        .map(|i| store.shard_of(i).unwrap())
        .collect();
    assert!(
        train_shards.len() >= 2,
        "the training clips span shards: {train_shards:?}"
    );
    let go = |run: &RunFolder, steps: u64, buffer: usize, resume: Option<std::path::PathBuf>| {
        let mut cfg = tiny(steps);
        cfg.train.checkpoint_every = 3;
        cfg.train.shuffle_buffer = buffer;
        train_framewise(&data, &cfg, run, resume)
    };
    // Batches of 4 of the store's ~8 training clips: 3 steps stop in the second epoch, between shards.
    let runs = dir.path().join("runs");
    let straight_run = RunFolder::create(&runs, "straight", "", &["rec", "kl"]).unwrap();
    let (straight, _) = go(&straight_run, 6, 2, None).unwrap();
    let split_run = RunFolder::create(&runs, "split", "", &["rec", "kl"]).unwrap();
    let (_, first) = go(&split_run, 3, 2, None).unwrap();
    let Outcome::Finished { checkpoint, .. } = first else {
        panic!("{first:?}")
    };
    let refused = go(&split_run, 6, 5, Some(checkpoint.clone())).unwrap_err().to_string();
    assert!(
        refused.contains("shuffle buffer of 2") && refused.contains("shuffle_buffer"),
        "{refused}"
    );
    let (resumed, _) = go(&split_run, 6, 2, Some(checkpoint)).unwrap();
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed VAE differs from straight training"
    );
}

#[test]
fn training_on_a_subset_of_frames_draws_frame_0_and_distinct_others() {
    use any4d_train::vae_loop::training_frames;
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    assert_eq!(training_frames(16, 0, &mut rng), (0..16).collect::<Vec<_>>());
    assert_eq!(training_frames(4, 4, &mut rng), vec![0, 1, 2, 3]);
    let mut seen = [false; 16];
    for _ in 0..50 {
        let f = training_frames(16, 4, &mut rng);
        assert_eq!(f.len(), 4);
        assert_eq!(f[0], 0, "{f:?}");
        assert!(f.windows(2).all(|w| w[0] < w[1]) && f[3] < 16, "{f:?}");
        f.iter().for_each(|&i| seen[i] = true);
    }
    assert!(seen.iter().all(|&s| s), "some frame was never drawn: {seen:?}");
}

#[test]
fn tiny_vae_trains_on_two_frames_per_clip_and_validates_on_all() {
    let _g = serial();
    let dir = tempfile::tempdir().unwrap();
    let data = synth_store(dir.path(), 3);
    let mut cfg = tiny(4);
    cfg.vae.train_frames = 2;
    let opts = RunOptions {
        data: data.clone(),
        runs_dir: dir.path().join("runs"),
        name: "vae".into(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
        parallel: None,
    };
    let (run, outcome) = train_vae(&cfg, &opts).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 4, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    assert!(t.rows.iter().all(|r| r.1.iter().all(|v| v.is_finite())), "{t:?}");
    // More frames than the clips have is an error naming the key.
    cfg.vae.train_frames = 5;
    let err = train_vae(&cfg, &opts).unwrap_err().to_string();
    assert!(err.contains("vae.train_frames = 5") && err.contains("4-frame"), "{err}");
    assert!(
        !dir.path().join("runs/vae-2").exists(),
        "a run folder was claimed by a run that cannot start"
    );
}

/// A micro-batch whose activations cannot fit the machine is refused with the estimate and the remedy before a run
/// folder is claimed; the estimate grows with the store's largest clip, the frames and the micro-batch.
#[test]
fn a_vae_micro_batch_too_large_for_memory_is_refused_before_a_run_starts() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_store(dir.path(), 3);
    let store = any4d_data::store::Store::open(&data).unwrap();
    let n = store.vertex_bound();
    let largest = (0..store.len())
        .map(|i| store.get(i).unwrap().clip.n_vertices)
        .max()
        .unwrap();
    assert!(
        n >= largest && n <= 2 * largest,
        "bound {n} for a largest clip of {largest} vertices"
    );
    let mut cfg = tiny(1);
    let est = |c: &VaeRunConfig, b: usize, f: usize| c.model.activation_bytes(b, f, n, c.vae.tokens);
    assert!(est(&cfg, 2, 4) > est(&cfg, 1, 4) && est(&cfg, 1, 4) > est(&cfg, 1, 2));
    assert!(cfg.model.activation_bytes(1, 4, 2 * n, cfg.vae.tokens) > est(&cfg, 1, 4));
    cfg.train.batch_size = 1 << 24;
    cfg.train.micro_batch = 1 << 24;
    let opts = RunOptions {
        data,
        runs_dir: dir.path().join("runs"),
        name: "huge".into(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
        parallel: None,
    };
    let Err(err) = train_vae(&cfg, &opts) else {
        panic!("a 2^24-clip micro-batch was accepted")
    };
    let err = err.to_string();
    assert!(
        err.contains("GiB of activations") && err.contains("train.micro_batch") && err.contains("vertices"),
        "{err}"
    );
    assert!(
        !dir.path().join("runs").join("huge-1").exists(),
        "no run folder is claimed"
    );
}
