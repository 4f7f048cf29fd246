//! The keyframe RF loop on a tiny frozen VAE (docs/method.md §4.5, §5.4): a short run lowers (R5), keyframe
//! masks follow the sampler (k ≤ k_max, k = 0 drawn; no keyframes for `none`/`replace_noised`), `impute_until`
//! trains on noisy keyframes, resume is bitwise equal to straight training (validation sampling on), `load_rf_run`
//! round-trips (and so do its packed copies, full and half precision), `--init` starts a new run from another
//! run's parameters, tokenizer and VAE, validation sampling writes seeded `samples.csv` rows at its steps for every
//! `conditioning` without touching the training streams, and mismatched configs or incomplete run folders give errors
//! naming the field or file. One tiny VAE run on
//! procedural clips is shared by all tests.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use any4d_data::keyframes::TrainingKeyframes;
use any4d_model::any_vae::AnyMeshVae;
use any4d_model::mmdit::KeyframeConditioning;
use any4d_model::text::scratch::ScratchTokenizer;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::config::Duration;
use any4d_train::devices::{Parallel, Strategy};
use any4d_train::loop_common::{Objective, Outcome, train};
use any4d_train::pack::{Precision as PackPrecision, pack_run};
use any4d_train::rf_loop::{
    INIT_FILE, LatentCache, LatentDraw, RF_TERMS, RfObjective, RfRunConfig, RfRunOptions, SAMPLE_TERMS, Subset,
    TextDropout, resume_rf, train_rf, training_mask,
};
use any4d_train::run_folder::{LOG_FILE, METRICS_FILE, RunFolder, SAMPLES_FILE, VALID_FILE, read_table};
use any4d_train::runs::{LoadedVae, VAE_RUN_FILE, load_rf_run, load_vae_run};
use burn::prelude::{Device, Tensor};
use common::{VaeFixture, copy_dir, params, quiet_setup, root, run_options, serial, vae_fixture};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The shared store and tiny VAE run (seed 1), made once per test process.
fn fixture() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture(1))
}

/// configs/rf/tiny.toml sized for the fixture: T = 4, k_max = 3, `steps` steps of 4 clips, no validation samples.
fn tiny_rf(steps: u64) -> RfRunConfig {
    let mut cfg = RfRunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).expect("configs/rf/tiny.toml");
    cfg.model.frames = 4;
    cfg.rf.k_max = 3;
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 4;
    cfg.train.checkpoint_every = steps;
    cfg.train.valid_every = steps;
    cfg.rf.valid_sample_every = 0;
    cfg
}

/// [`tiny_rf`] with validation samples of 2 VAL clips on a 4-point grid every `every` steps.
fn sampling_rf(steps: u64, every: u64) -> RfRunConfig {
    let mut cfg = tiny_rf(steps);
    cfg.train.valid_every = every;
    cfg.rf.valid_sample_every = every;
    cfg.rf.valid_sample_clips = 2;
    cfg.rf.valid_sample_grid = 4;
    cfg
}

fn rf_opts(name: &str) -> RfRunOptions {
    let f = fixture();
    RfRunOptions {
        run: run_options(&f.store, &f.dir, name),
        vae_run: Some(f.vae_run.clone()),
        init: None,
        latents: None,
    }
}

const LOSS_STEPS: u64 = 100;

/// The RF run of [`tiny_rf_run_lowers_its_loss`], trained once and shared with the round-trip test.
fn trained_rf() -> &'static (PathBuf, RfRunConfig) {
    static RUN: OnceLock<(PathBuf, RfRunConfig)> = OnceLock::new();
    RUN.get_or_init(|| {
        let mut cfg = tiny_rf(LOSS_STEPS);
        // The fixture VAE is barely trained: its posterior σ dwarfs μ, so sampled latents are nearly pure
        // noise, whose best (R5) is ≈ 1.57 against 2 at the start (nothing to learn). Its means are
        // clip-specific and learnable.
        cfg.rf.latent = LatentDraw::Mean;
        let (run, outcome) = train_rf(&cfg, &rf_opts("rf")).expect("tiny RF run");
        assert!(
            matches!(outcome, Outcome::Finished { steps: LOSS_STEPS, .. }),
            "{outcome:?}"
        );
        (run.root().to_path_buf(), cfg)
    })
}

fn inference_device() -> Device {
    device(Backend::Flex, Precision::F32).expect("flex device")
}

/// A folder with one tokenizer trained on the fixture's TRAIN captions, made once per test process: WordPiece
/// training does not always give the same vocabulary size (175 or 176 here), so objectives that must agree share it.
fn tokenizer_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let f = fixture();
        let store = any4d_data::store::Store::open(&f.store).unwrap();
        let captions: Vec<String> = store
            .indices(any4d_data::store::Split::Train)
            .into_iter()
            .map(|i| store.get(i).unwrap().clip.caption)
            .collect();
        let vocab_size = tiny_rf(1).text.vocab_size;
        let tokenizer = ScratchTokenizer::train(&captions, vocab_size).unwrap();
        let dir = f.dir.join("tokenizer");
        std::fs::create_dir_all(&dir).unwrap();
        tokenizer.save(&dir).unwrap();
        dir
    })
}

fn make_objective(cfg: &RfRunConfig, vae: &LoadedVae, dev: &Device) -> (RfObjective, usize) {
    let f = fixture();
    let tokenizer = ScratchTokenizer::load(tokenizer_dir()).unwrap();
    let vocab = tokenizer.vocab_size();
    (
        RfObjective::new(cfg, &f.store, None, vae, tokenizer, dev).unwrap(),
        vocab,
    )
}

#[test]
fn tiny_rf_run_lowers_its_loss() {
    let _g = serial();
    let (run, _) = trained_rf();
    let t = read_table(&run.join(METRICS_FILE)).unwrap();
    let col = |name: &str| t.header.iter().position(|h| h == name).unwrap() - 1;
    let (loss, kf) = (col("loss"), col("kf_frac"));
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[loss]).sum::<f64>() / rows.len() as f64;
    let n = t.rows.len();
    assert_eq!(n as u64, LOSS_STEPS);
    let (first, last) = (mean(&t.rows[..10]), mean(&t.rows[n - 10..]));
    assert!(
        last < 0.8 * first,
        "RF loss did not drop: first 10 steps {first}, last 10 {last}"
    );
    // input_mask with k ~ U{0..3} of T = 4: keyframes appear, but not in every slot.
    let kf_mean = t.rows.iter().map(|r| r.1[kf]).sum::<f64>() / n as f64;
    assert!((0.1..0.7).contains(&kf_mean), "mean keyframe fraction {kf_mean}");
    for file in ["tokenizer.json", VAE_RUN_FILE, VALID_FILE] {
        assert!(run.join(file).is_file(), "{file} missing in {}", run.display());
    }
}

#[test]
fn load_rf_run_round_trips_the_trained_run() {
    let _g = serial();
    let (run, cfg) = trained_rf();
    let dev = inference_device();
    let loaded = load_rf_run(run, &dev).unwrap();
    assert_eq!(&loaded.config, cfg);
    assert_eq!(loaded.step, LOSS_STEPS);
    let vae = loaded.load_vae(&dev).unwrap();
    assert_eq!(vae.run, std::fs::canonicalize(&fixture().vae_run).unwrap());
    // The loaded network reproduces the final validation loss logged by the run (fixed validation seed).
    let tokenizer = ScratchTokenizer::load(run).unwrap();
    assert_eq!(tokenizer.vocab_size(), loaded.tokenizer.vocab_size());
    let objective = RfObjective::new(cfg, &fixture().store, None, &vae, tokenizer, &dev).unwrap();
    let values = objective
        .validate(&loaded.model, &dev, loaded.step)
        .unwrap()
        .expect("the fixture store has VAL clips");
    let table = read_table(&run.join(VALID_FILE)).unwrap();
    let (step, logged) = table.rows.last().expect("a validation row");
    assert_eq!(*step, LOSS_STEPS);
    let rel = (values[2] - logged[2]).abs() / logged[2];
    assert!(rel < 1e-5, "validation loss {} vs logged {}", values[2], logged[2]);
    let text = loaded
        .encode_text(&["a small sphere spins".into(), String::new()], &dev)
        .unwrap();
    assert_eq!(text.dims(), [2, cfg.text.max_len, cfg.model.text_dim]);
}

/// `any4d model pack`: the packed VAE and RF load where the runs do, with the recorded VAE redirected beside the RF;
/// full precision keeps every parameter, half precision is within f16 rounding and half the size; an existing
/// output and `--vae-at` on a VAE run are refused, leaving nothing behind.
#[test]
fn packed_runs_load_with_their_parameters_in_full_and_half_precision() {
    let _g = serial();
    let (run, _) = trained_rf();
    let dev = inference_device();
    let out = tempfile::tempdir().unwrap();
    let original = load_rf_run(run, &dev).unwrap();
    let want = params(&original.model);
    let mut sizes = Vec::new();
    for (precision, tol) in [(PackPrecision::Full, 0.0f32), (PackPrecision::Half, 1.0 / 1024.0)] {
        let dir = out.path().join(format!("{precision:?}"));
        let vae = pack_run(&fixture().vae_run, &dir.join("vae"), precision, None, &dev).unwrap();
        assert_eq!((vae.kind, vae.averaged), ("VAE", false));
        let rf = pack_run(run, &dir.join("rf"), precision, Some(Path::new("../vae")), &dev).unwrap();
        assert_eq!((rf.kind, rf.step), ("RF", LOSS_STEPS));
        sizes.push(rf.model_bytes);
        let packed = load_rf_run(&dir.join("rf"), &dev).unwrap();
        assert_eq!(packed.config, original.config);
        let loaded_vae = packed.load_vae(&dev).unwrap();
        assert_eq!(loaded_vae.run, std::fs::canonicalize(dir.join("vae")).unwrap());
        assert_eq!(loaded_vae.stats, load_vae_run(&fixture().vae_run, &dev).unwrap().stats);
        assert!(
            !dir.join("rf/checkpoints")
                .join(format!("step_{LOSS_STEPS}/optim.bpk"))
                .exists()
        );
        let got = params(&packed.model);
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= tol * w.abs().max(1e-3), "{precision:?}: {g} vs {w}");
        }
        if precision == PackPrecision::Full {
            assert_eq!(got, want);
        }
        // Loading casts back: the network computes in f32 and agrees with the original within f16 rounding.
        let caption = ["a small sphere spins".to_string()];
        let text = packed.encode_text(&caption, &dev).unwrap();
        assert_eq!(text.dtype(), burn::tensor::DType::F32);
        let diff = (text - original.encode_text(&caption, &dev).unwrap())
            .abs()
            .max()
            .into_scalar::<f32>();
        assert!(diff <= 64.0 * tol, "{precision:?}: text states differ by {diff}");
    }
    assert!(sizes[1] * 10 < sizes[0] * 6, "half precision sizes {sizes:?}");
    let existing = out.path().join("Full/rf");
    let err = pack_run(run, &existing, PackPrecision::Full, None, &dev)
        .unwrap_err()
        .to_string();
    assert!(err.contains("exists"), "{err}");
    let bad = out.path().join("vae-at");
    let err = pack_run(
        &fixture().vae_run,
        &bad,
        PackPrecision::Full,
        Some(Path::new("x")),
        &dev,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("RF and latent BD-LSTM runs only"), "{err}");
    assert!(!bad.exists());
}

/// `model export` then `model import`, under any4d's names and AnimateAnyMesh's: the same parameters, config,
/// statistics and side files come back, and what cannot be imported says why.
#[test]
fn exported_runs_import_with_their_parameters_under_both_names() {
    use any4d_model::interop::Names;
    use any4d_train::interop::{MODEL_SAFETENSORS, export_run, import_file};
    let _g = serial();
    let (run, _) = trained_rf();
    let dev = inference_device();
    let out = tempfile::tempdir().unwrap();
    let original = load_rf_run(run, &dev).unwrap();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    for names in [Names::Any4d, Names::AnimateAnyMesh] {
        let dir = out.path().join(names.name());
        let e = export_run(run, &dir.join("rf-export"), names, &dev).unwrap();
        assert_eq!((e.network.name(), e.step), ("mmdit", LOSS_STEPS));
        let i = import_file(
            &dir.join("rf-export").join(MODEL_SAFETENSORS),
            &dir.join("rf"),
            None,
            None,
            &dev,
        )
        .unwrap();
        assert_eq!((i.names, i.step, i.ignored), (names, LOSS_STEPS, 0));
        let back = load_rf_run(&dir.join("rf"), &dev).unwrap();
        assert_eq!(back.config, original.config);
        assert_eq!(params(&back.model), params(&original.model), "{names:?}");
        let e = export_run(&fixture().vae_run, &dir.join("vae-export"), names, &dev).unwrap();
        assert_eq!(e.network.name(), "frame_vae");
        import_file(
            &dir.join("vae-export").join(MODEL_SAFETENSORS),
            &dir.join("vae"),
            None,
            None,
            &dev,
        )
        .unwrap();
        let back = load_vae_run(&dir.join("vae"), &dev).unwrap();
        assert_eq!(back.stats, vae.stats);
        let (a, b) = match (&back.model, &vae.model) {
            (AnyMeshVae::Framewise(a), AnyMeshVae::Framewise(b)) => (params(a), params(b)),
            _ => panic!("a frame-wise VAE"),
        };
        assert_eq!(a, b, "{names:?}");
    }
    // Under the other names' claim, with a config of another network, as a pickle, or without its side files.
    let export = out.path().join("any4d/rf-export");
    let model = export.join(MODEL_SAFETENSORS);
    let err = |r: any4d_train::error::Result<_>| r.map(|_: any4d_train::interop::Imported| ()).unwrap_err().to_string();
    let e = err(import_file(
        &model,
        &out.path().join("x1"),
        None,
        Some(Names::AnimateAnyMesh),
        &dev,
    ));
    assert!(
        e.contains("not a parameter of the mmdit under animateanymesh names"),
        "{e}"
    );
    let vae_cfg = fixture().vae_run.join("config.toml");
    let e = err(import_file(&model, &out.path().join("x2"), Some(&vae_cfg), None, &dev));
    assert!(e.contains("holds a mmdit but the config describes a frame_vae"), "{e}");
    let pt = out.path().join("model.pt");
    std::fs::write(&pt, b"\x80\x02cos\nsystem\n").unwrap();
    let names = Some(Names::AnimateAnyMesh);
    let e = err(import_file(&pt, &out.path().join("x3"), Some(&vae_cfg), names, &dev));
    assert!(e.contains("burn's reader can read"), "{e}");
    std::fs::remove_file(export.join("tokenizer.json")).unwrap();
    let e = err(import_file(&model, &out.path().join("x4"), None, None, &dev));
    assert!(e.contains("tokenizer.json"), "{e}");
    for x in ["x1", "x2", "x3", "x4"] {
        assert!(
            !out.path().join(x).exists() && !out.path().join(format!(".tmp_import_{x}")).exists(),
            "{x}"
        );
    }
    let e = export_run(run, &export, Names::Any4d, &dev).unwrap_err().to_string();
    assert!(e.contains("exists"), "{e}");
}

#[test]
fn keyframe_masks_follow_sampler_and_mode() {
    let cfg = RfRunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut hist = [0usize; 17];
    for _ in 0..3000 {
        let m = training_mask(&cfg.rf, KeyframeConditioning::InputMask, 16, &mut rng);
        assert_eq!(m.len(), 16);
        hist[m.iter().filter(|&&x| x).count()] += 1;
    }
    assert!(hist[6..].iter().all(|&n| n == 0), "k > k_max = 5 drawn: {hist:?}");
    // k ~ U{0..5}: 500 expected per value; 4.5 standard deviations ≈ 92.
    assert!(hist[..6].iter().all(|&n| (400..=600).contains(&n)), "{hist:?}");
    for mode in [KeyframeConditioning::None, KeyframeConditioning::ReplaceNoised] {
        for _ in 0..100 {
            assert!(
                training_mask(&cfg.rf, mode, 16, &mut rng).iter().all(|&m| !m),
                "{mode:?}"
            );
        }
    }
    let mut scenemi = cfg.rf.clone();
    scenemi.kf_sampler = TrainingKeyframes::Scenemi;
    let mut ks = std::collections::BTreeSet::new();
    for _ in 0..2000 {
        let m = training_mask(&scenemi, KeyframeConditioning::ImputeUntil, 16, &mut rng);
        assert!(m[0] && m[15], "SceneMI keeps first and last: {m:?}");
        ks.insert(m.iter().filter(|&&x| x).count());
    }
    assert_eq!(ks, (2..=16).collect(), "SceneMI k ~ U{{2..T}}");
}

#[test]
fn batch_masks_respect_k_max_and_none_has_no_keyframes() {
    let _g = serial();
    let dev = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    let mut cfg = tiny_rf(1);
    let (objective, vocab) = make_objective(&cfg, &vae, &dev);
    let model = cfg.model_config(vocab).init(&dev);
    let n = objective.train_len();
    let all: Vec<usize> = (0..n).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut sums = Vec::new();
    for _ in 0..50 {
        let step = objective
            .batcher()
            .batch(&model, Subset::Train, &all, &mut rng, TextDropout::Apply, &dev)
            .unwrap();
        assert_eq!(step.batch.z.dims(), [n, 32, 4, 4]);
        assert_eq!(step.batch.mask.dims(), [n, 4]);
        let rows: Vec<f32> = step.batch.mask.sum_dim(1).into_data().try_to_vec().unwrap();
        sums.extend(rows);
    }
    assert!(sums.iter().all(|&k| k <= 3.0), "k > k_max = 3: {sums:?}");
    assert!(sums.contains(&0.0), "k = 0 never drawn in {} masks", sums.len());
    assert!(sums.contains(&3.0), "k = 3 never drawn in {} masks", sums.len());

    cfg.model.conditioning = KeyframeConditioning::None;
    let (objective, vocab) = make_objective(&cfg, &vae, &dev);
    let model = cfg.model_config(vocab).init(&dev);
    for _ in 0..5 {
        let step = objective
            .batcher()
            .batch(&model, Subset::Train, &all, &mut rng, TextDropout::Apply, &dev)
            .unwrap();
        let total = step.batch.mask.sum().into_scalar::<f32>();
        assert_eq!(total, 0.0, "conditioning none drew keyframes");
    }
}

/// The configured text-dropout rate is the fraction of keep_txt = 0 in training batches (within 4.5 σ of a
/// binomial), 0 disables it, and validation batches keep every caption.
#[test]
fn text_dropout_rate_reaches_the_batch() {
    let _g = serial();
    let dev = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    for rate in [0.0, 0.3] {
        let mut cfg = tiny_rf(1);
        cfg.rf.text_dropout = rate;
        let (objective, vocab) = make_objective(&cfg, &vae, &dev);
        let model = cfg.model_config(vocab).init(&dev);
        let all: Vec<usize> = (0..objective.train_len()).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut dropped, mut total) = (0usize, 0usize);
        for _ in 0..60 {
            let step = objective
                .batcher()
                .batch(&model, Subset::Train, &all, &mut rng, TextDropout::Apply, &dev)
                .unwrap();
            let keep: Vec<f32> = step.batch.keep_txt.into_data().try_to_vec().unwrap();
            assert!(keep.iter().all(|&k| k == 0.0 || k == 1.0), "{keep:?}");
            dropped += keep.iter().filter(|&&k| k == 0.0).count();
            total += keep.len();
        }
        let frac = dropped as f64 / total as f64;
        let sigma = (rate * (1.0 - rate) / total as f64).sqrt();
        assert!(
            (frac - rate).abs() <= 4.5 * sigma + 1e-12,
            "rate {rate}: dropped {frac} of {total}"
        );
        let valid = objective
            .batcher()
            .batch(&model, Subset::Train, &all, &mut rng, TextDropout::Off, &dev)
            .unwrap();
        assert_eq!(valid.batch.keep_txt.sum().into_scalar::<f32>(), all.len() as f32);
    }
}

#[test]
fn per_batch_encoding_matches_the_memory_cache() {
    let _g = serial();
    let dev = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    let mut cfg = tiny_rf(1);
    cfg.rf.latent = LatentDraw::Mean;
    let (cached, vocab) = make_objective(&cfg, &vae, &dev);
    cfg.rf.latent_cache = LatentCache::PerBatch;
    let (per_batch, _) = make_objective(&cfg, &vae, &dev);
    assert!(cached.cached_bytes() > 0 && per_batch.cached_bytes() == 0);
    let model = cfg.model_config(vocab).init(&dev);
    let draw = |o: &RfObjective| {
        dev.seed(5);
        let step = o
            .batcher()
            .batch(
                &model,
                Subset::Train,
                &[4, 0, 2],
                &mut ChaCha8Rng::seed_from_u64(5),
                TextDropout::Apply,
                &dev,
            )
            .unwrap();
        (step.batch.z0, step.batch.z, step.batch.mask)
    };
    let (a, b) = (draw(&cached), draw(&per_batch));
    let max_diff = |x: Tensor<4>, y: Tensor<4>| (x - y).abs().max().into_scalar::<f32>();
    assert!(max_diff(a.0.unsqueeze(), b.0.unsqueeze()) < 1e-5, "z0 differs");
    assert!(max_diff(a.1, b.1) < 1e-5, "z differs");
    assert!(max_diff(a.2.unsqueeze(), b.2.unsqueeze()) == 0.0, "masks differ");
}

#[test]
fn impute_until_trains_on_noisy_keyframes() {
    let _g = serial();
    let mut cfg = tiny_rf(3);
    cfg.model.conditioning = KeyframeConditioning::ImputeUntil;
    cfg.rf.kf_sampler = TrainingKeyframes::Scenemi;
    cfg.rf.keyframe_noise = 0.5; // large, so the encoded keyframes must differ from the clean latents
    cfg.rf.latent = LatentDraw::Mean; // Z = standardized clean μ: comparable with the noisy keyframes' μ
    let dev = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    let (objective, vocab) = make_objective(&cfg, &vae, &dev);
    let model = cfg.model_config(vocab).init(&dev);
    let all: Vec<usize> = (0..objective.train_len()).collect();
    let step = objective
        .batcher()
        .batch(
            &model,
            Subset::Train,
            &all,
            &mut ChaCha8Rng::seed_from_u64(2),
            TextDropout::Off,
            &dev,
        )
        .unwrap();
    let b = all.len();
    let mask: Vec<f32> = step.batch.mask.clone().into_data().try_to_vec().unwrap();
    assert!(
        mask.chunks(4).all(|m| m[0] == 1.0 && m[3] == 1.0),
        "SceneMI keeps first and last: {mask:?}"
    );
    // Mean |z_key − z| per (clip, frame): only inner keyframes are noised; first, last and non-keyframes are clean.
    let diff: Vec<f32> = (step.batch.z_key.clone() - step.batch.z.clone())
        .abs()
        .mean_dim(3)
        .mean_dim(1)
        .reshape([b, 4])
        .into_data()
        .try_to_vec()
        .unwrap();
    let mut noisy = 0;
    for (i, (&d, &m)) in diff.iter().zip(&mask).enumerate() {
        let f = i % 4;
        if m == 1.0 && f != 0 && f != 3 {
            noisy += 1;
        } else {
            assert!(d < 1e-4, "clip {} frame {f} (mask {m}) changed by {d}", i / 4);
        }
    }
    let noisy_mean = diff
        .iter()
        .zip(&mask)
        .enumerate()
        .filter(|(i, (_, m))| **m == 1.0 && i % 4 != 0 && i % 4 != 3)
        .map(|(_, (d, _))| *d)
        .sum::<f32>()
        / noisy.max(1) as f32;
    assert!(
        noisy > 0 && noisy_mean > 1e-3,
        "{noisy} noisy keyframes, mean latent change {noisy_mean}"
    );
    let (run, outcome) = train_rf(&cfg, &rf_opts("impute")).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 3, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    assert!(t.rows.iter().all(|r| r.1.iter().all(|v| v.is_finite())), "{t:?}");
}

#[test]
fn tiny_rf_resume_is_bitwise_equal_to_straight_training() {
    let _g = serial();
    let n = 2;
    let inference = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &inference).unwrap();
    // Validation and sampling after every step: they must not disturb the training streams.
    let cfg = sampling_rf(2 * n, 1);
    let go = |objective: &RfObjective, vocab: usize, run: &RunFolder, steps: u64, resume: Option<PathBuf>| {
        let mut cfg = cfg.clone();
        cfg.train.duration = Duration::Steps(steps);
        let dev = inference.clone().autodiff();
        dev.seed(cfg.train.seed);
        let model = cfg.model_config(vocab).init(&dev);
        train(objective, model, quiet_setup(run, &cfg.train, &cfg.optim, dev, resume)).unwrap()
    };
    let sampling_objective = |run: &RunFolder| {
        let (mut objective, vocab) = make_objective(&cfg, &vae, &inference);
        objective.log_validation_samples(run).unwrap();
        (objective, vocab)
    };
    let runs = fixture().dir.join("resume-runs");
    let straight_run = RunFolder::create(&runs, "straight", "", &RF_TERMS).unwrap();
    let (objective, vocab) = sampling_objective(&straight_run);
    let (straight, _) = go(&objective, vocab, &straight_run, 2 * n, None);
    let split_run = RunFolder::create(&runs, "split", "", &RF_TERMS).unwrap();
    let (objective, vocab) = sampling_objective(&split_run);
    let (_, first) = go(&objective, vocab, &split_run, n, None);
    let Outcome::Finished { checkpoint, .. } = first else {
        panic!("{first:?}")
    };
    let (resumed, _) = go(&objective, vocab, &split_run, 2 * n, Some(checkpoint));
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed RF differs from straight training"
    );
    let straight_samples = read_table(&straight_run.path(SAMPLES_FILE)).unwrap();
    let steps: Vec<u64> = straight_samples.rows.iter().map(|r| r.0).collect();
    assert_eq!(steps, (1..=2 * n).collect::<Vec<_>>());
    assert_eq!(
        straight_samples,
        read_table(&split_run.path(SAMPLES_FILE)).unwrap(),
        "resumed run sampled different scores"
    );
    // The same run without sampling trains the same weights: sampling leaves the training streams alone.
    let plain_run = RunFolder::create(&runs, "plain", "", &RF_TERMS).unwrap();
    let (objective, vocab) = make_objective(&cfg, &vae, &inference);
    let (plain, _) = go(&objective, vocab, &plain_run, 2 * n, None);
    assert_eq!(
        params(&straight),
        params(&plain),
        "validation sampling changed training"
    );
    assert!(!plain_run.path(SAMPLES_FILE).exists());
}

#[test]
fn validation_samples_are_logged_at_their_steps_and_seeded() {
    let _g = serial();
    // 3 steps, validations at 2 and 3 (the end): samples at both.
    let cfg = sampling_rf(3, 2);
    let (run, outcome) = train_rf(&cfg, &rf_opts("samples")).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 3, .. }), "{outcome:?}");
    let table = read_table(&run.path(SAMPLES_FILE)).unwrap();
    let mut header = vec!["step"];
    header.extend(SAMPLE_TERMS);
    assert_eq!(table.header, header);
    assert_eq!(table.rows.iter().map(|r| r.0).collect::<Vec<_>>(), [2, 3]);
    for (step, values) in &table.rows {
        assert!(
            values.iter().all(|v| v.is_finite() && *v >= 0.0),
            "step {step}: {values:?}"
        );
        // An untrained RF does not reproduce the non-keyframes.
        assert!(values[0] > 0.0, "step {step}: zero RMSE");
    }
    let log = std::fs::read_to_string(run.path(LOG_FILE)).unwrap();
    assert_eq!(
        log.matches("validation samples (2 clips, 4-point grid)").count(),
        2,
        "{log}"
    );

    // The final checkpoint (with the run's own tokenizer) reproduces the last row: the scores are seeded.
    let dev = inference_device();
    let loaded = load_rf_run(run.root(), &dev).unwrap();
    let vae = loaded.load_vae(&dev).unwrap();
    let tokenizer = ScratchTokenizer::load(run.root()).unwrap();
    let objective = RfObjective::new(&cfg, &fixture().store, None, &vae, tokenizer, &dev).unwrap();
    let scores = objective
        .validation_samples(&loaded.model, &dev)
        .unwrap()
        .expect("the fixture store has VAL clips");
    assert_eq!(scores.clips, 2);
    let logged = &table.rows[1].1;
    for (name, (got, want)) in SAMPLE_TERMS
        .iter()
        .zip([scores.rmse, scores.chamfer, scores.dtw].iter().zip(logged))
    {
        assert!(
            (got - want).abs() <= 1e-5 * want.abs().max(1e-6),
            "{name}: {got} vs logged {want}"
        );
    }

    // Sampling off: no samples.csv, no log line.
    let mut off = cfg.clone();
    off.rf.valid_sample_every = 0;
    let (run, _) = train_rf(&off, &rf_opts("no-samples")).unwrap();
    assert!(!run.path(SAMPLES_FILE).exists(), "sampling off wrote samples.csv");
    let log = std::fs::read_to_string(run.path(LOG_FILE)).unwrap();
    assert!(!log.contains("validation samples"), "{log}");
}

#[test]
fn validation_samples_run_for_every_kf_mode() {
    let _g = serial();
    let dev = inference_device();
    let vae = load_vae_run(&fixture().vae_run, &dev).unwrap();
    for mode in [
        KeyframeConditioning::InputMask,
        KeyframeConditioning::ReplaceNoised,
        KeyframeConditioning::None,
        KeyframeConditioning::ImputeUntil,
    ] {
        let mut cfg = sampling_rf(1, 1);
        cfg.model.conditioning = mode;
        cfg.rf.valid_sample_clips = 5; // more than the 3 VAL clips: all of them
        let (objective, vocab) = make_objective(&cfg, &vae, &dev);
        dev.seed(1);
        let model = cfg.model_config(vocab).init(&dev);
        let a = objective.validation_samples(&model, &dev).unwrap().expect("VAL clips");
        assert_eq!(a.clips, 3, "{mode:?}");
        assert!(
            [a.rmse, a.chamfer, a.dtw].iter().all(|v| v.is_finite() && *v >= 0.0) && a.rmse > 0.0,
            "{mode:?}: {a:?}"
        );
        let b = objective.validation_samples(&model, &dev).unwrap().expect("VAL clips");
        assert_eq!(a, b, "{mode:?}: not seeded");
    }
}

/// `--init`: a new run starts from another run's parameters, tokenizer and VAE (one step at a vanishing learning
/// rate leaves the parameters, and an average started from them, where they were; a fresh run of the same config is
/// elsewhere), and a different network, caption encoder or VAE, a source checkpoint without parameters, or `--init`
/// on a resume, is refused before a run folder is claimed.
#[test]
fn init_starts_a_new_run_from_another_runs_parameters() {
    let _g = serial();
    let f = fixture();
    let (source, source_cfg) = trained_rf();
    let dev = inference_device();
    let before = params(&load_rf_run(source, &dev).unwrap().model);
    let mut cfg = source_cfg.clone();
    cfg.train.duration = Duration::Steps(1);
    cfg.train.checkpoint_every = 1;
    cfg.train.valid_every = 1;
    cfg.optim.lr = 1e-30;
    let init_opts = |name: &str, vae_run: Option<PathBuf>| RfRunOptions {
        init: Some(source.clone()),
        latents: None,
        vae_run,
        ..rf_opts(name)
    };
    let (run, outcome) = train_rf(&cfg, &init_opts("init", None)).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 1, .. }), "{outcome:?}");
    let loaded = load_rf_run(run.root(), &dev).unwrap();
    let max_diff = |a: &[f32], b: &[f32]| {
        assert_eq!(a.len(), b.len(), "parameter counts differ");
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max)
    };
    let moved = max_diff(&before, &params(&loaded.model));
    assert!(moved < 1e-6, "the initialised run moved its parameters by {moved}");
    assert_eq!(
        std::fs::read(run.root().join("tokenizer.json")).unwrap(),
        std::fs::read(source.join("tokenizer.json")).unwrap(),
        "the initialised run must keep the source's tokenizer"
    );
    assert_eq!(loaded.vae.run, std::fs::canonicalize(&f.vae_run).unwrap());
    let log = std::fs::read_to_string(run.root().join(LOG_FILE)).unwrap();
    assert!(log.contains("parameters initialised from"), "{log}");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.root().join(INIT_FILE)).unwrap()).unwrap();
    assert_eq!(record["step"], LOSS_STEPS);
    let named = std::path::PathBuf::from(record["checkpoint"].as_str().unwrap());
    assert_eq!(
        named,
        std::fs::canonicalize(source.join(format!("checkpoints/step_{LOSS_STEPS}"))).unwrap()
    );
    // A packed fine-tune keeps the record of where its parameters started; a packed fresh run has none.
    let packed = f.dir.join("init-packed");
    let _ = std::fs::remove_dir_all(&packed);
    pack_run(run.root(), &packed, PackPrecision::Full, None, &dev).unwrap();
    assert_eq!(
        std::fs::read(packed.join(INIT_FILE)).unwrap(),
        std::fs::read(run.root().join(INIT_FILE)).unwrap()
    );
    let packed_source = f.dir.join("init-source-packed");
    let _ = std::fs::remove_dir_all(&packed_source);
    pack_run(source, &packed_source, PackPrecision::Full, None, &dev).unwrap();
    assert!(!packed_source.join(INIT_FILE).exists());
    // A run that keeps an average starts it from the loaded parameters.
    let mut averaged = cfg.clone();
    averaged.train.ema_decay = 0.99;
    let (run_avg, _) = train_rf(&averaged, &init_opts("init-avg", None)).unwrap();
    assert!(run_avg.root().join("checkpoints/step_1/ema.bpk").is_file());
    let moved = max_diff(&before, &params(&load_rf_run(run_avg.root(), &dev).unwrap().model));
    assert!(moved < 1e-6, "the initialised run's average moved by {moved}");
    // The same config from scratch is elsewhere: the comparison above can fail.
    let (fresh, _) = train_rf(&cfg, &rf_opts("init-fresh")).unwrap();
    let fresh = params(&load_rf_run(fresh.root(), &dev).unwrap().model);
    assert!(
        fresh.len() != before.len() || max_diff(&before, &fresh) > 1e-3,
        "a fresh run landed on the trained parameters"
    );

    let mut bad = cfg.clone();
    bad.model.blocks += 1;
    let err = train_rf(&bad, &init_opts("init-bad", None)).unwrap_err().to_string();
    assert!(
        err.contains("--init") && err.contains("[model]") && err.contains("blocks"),
        "{err}"
    );
    let mut bad = cfg.clone();
    bad.text.layers += 1;
    let err = train_rf(&bad, &init_opts("init-bad", None)).unwrap_err().to_string();
    assert!(err.contains("[text]") && err.contains("layers"), "{err}");
    let err = train_rf(&cfg, &init_opts("init-bad", Some(f.store.clone())))
        .unwrap_err()
        .to_string();
    assert!(err.contains("differs from the VAE run"), "{err}");
    // A source checkpoint without its parameters is refused before a run folder is claimed.
    let hollow = f.dir.join("init-hollow");
    copy_dir(source, &hollow);
    for ckpt in std::fs::read_dir(hollow.join("checkpoints")).unwrap() {
        std::fs::remove_file(ckpt.unwrap().path().join("model.bpk")).unwrap();
    }
    let hollow_opts = RfRunOptions {
        init: Some(hollow.clone()),
        ..init_opts("init-bad", None)
    };
    let err = train_rf(&cfg, &hollow_opts).unwrap_err().to_string();
    assert!(err.contains("--init") && err.contains("model.bpk"), "{err}");
    assert!(
        !f.dir.join("runs/init-bad-1").exists(),
        "a refused start claimed a run folder"
    );
    let err = resume_rf(run.root(), None, &init_opts("init-bad", None))
        .unwrap_err()
        .to_string();
    assert!(err.contains("--init starts a new run"), "{err}");
}

#[test]
fn mismatched_configs_and_incomplete_runs_are_reported() {
    let _g = serial();
    let f = fixture();
    let mut cfg = tiny_rf(1);
    cfg.model.channels = 3;
    let err = train_rf(&cfg, &rf_opts("bad")).unwrap_err().to_string();
    assert!(
        err.contains("model.channels") && err.contains("latent_channels = 4"),
        "{err}"
    );
    let mut cfg = tiny_rf(1);
    cfg.model.frames = 16;
    let err = train_rf(&cfg, &rf_opts("bad")).unwrap_err().to_string();
    assert!(err.contains("model.frames") && err.contains("4-frame"), "{err}");
    assert!(
        !f.dir.join("runs/bad-1").exists(),
        "a failed start claimed a run folder"
    );

    let dev = inference_device();
    let empty = f.dir.join("not-a-run");
    std::fs::create_dir_all(&empty).unwrap();
    let err = load_vae_run(&empty, &dev).unwrap_err().to_string();
    assert!(err.contains("not-a-run") && err.contains("config.toml"), "{err}");
    // An RF run folder without its tokenizer.
    std::fs::copy(root().join("configs/rf/tiny.toml"), empty.join("config.toml")).unwrap();
    let err = load_rf_run(&empty, &dev).err().expect("no tokenizer").to_string();
    assert!(err.contains("not-a-run") && err.contains("tokenizer.json"), "{err}");
    // A VAE run folder without latent statistics (a copy of the fixture's without `latent_stats.json`).
    let vae_copy = f.dir.join("vae-without-stats");
    copy_dir(&f.vae_run, &vae_copy);
    std::fs::remove_file(vae_copy.join("latent_stats.json")).unwrap();
    let err = load_vae_run(&vae_copy, &dev).unwrap_err().to_string();
    assert!(
        err.contains("vae-without-stats") && err.contains("latent_stats.json"),
        "{err}"
    );
}

#[test]
fn validation_sampling_keys_are_checked() {
    let path = root().join("configs/rf/tiny.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let parse = |t: &str| RfRunConfig::parse(t, &path).map(|_| ()).map_err(|e| e.to_string());
    parse(&text).unwrap();
    let err = parse(&text.replacen("valid_sample_every = 20", "valid_sample_every = 30", 1)).unwrap_err();
    assert!(
        err.contains("tiny.toml") && err.contains("rf.valid_sample_every 30") && err.contains("train.valid_every 20"),
        "{err}"
    );
    parse(&text.replacen("valid_sample_every = 20", "valid_sample_every = 0", 1)).unwrap();
    let err = parse(&text.replacen("valid_sample_grid = 8", "valid_sample_grid = 1", 1)).unwrap_err();
    assert!(err.contains("rf.valid_sample_grid 1"), "{err}");
    let err = parse(&text.replacen("valid_sample_clips = 2", "valid_sample_clips = 0", 1)).unwrap_err();
    assert!(err.contains("rf.valid_sample_clips"), "{err}");
    let err = parse(&text.replacen("valid_sample_clips = 2\n", "", 1)).unwrap_err();
    assert!(err.contains("valid_sample_clips"), "missing key accepted: {err}");
}

#[test]
fn tiny_rf_trains_and_resumes_over_two_cpu_devices() {
    let _g = serial();
    let mut cfg = tiny_rf(3);
    cfg.train.micro_batch = 2;
    cfg.train.checkpoint_every = 1;
    let mut opts = rf_opts("parallel");
    opts.run.parallel = Some(Parallel::parse("flex,flex", Strategy::Auto).unwrap());
    let (run, outcome) = train_rf(&cfg, &opts).expect("data-parallel RF run");
    assert!(matches!(outcome, Outcome::Finished { steps: 3, .. }), "{outcome:?}");
    let log = std::fs::read_to_string(run.path(LOG_FILE)).unwrap();
    assert!(log.contains("data-parallel over 2 devices (MainDevice)"), "{log}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    assert_eq!(t.rows.len(), 3);
    assert!(t.rows.iter().all(|r| r.1.iter().all(|v| v.is_finite())), "{t:?}");
    // Resuming a finished run over the devices is a no-op that still loads the checkpoint and the VAE.
    let again = resume_rf(run.root(), None, &opts).expect("resume over two devices");
    assert!(matches!(again, Outcome::Finished { steps: 3, .. }), "{again:?}");
}

#[test]
fn a_micro_batch_too_large_for_memory_is_refused_before_a_run_starts() {
    let _g = serial();
    let mut cfg = tiny_rf(1);
    // 2^20 clips per micro-batch: terabytes of activations at any width.
    cfg.train.batch_size = 1 << 20;
    cfg.train.micro_batch = 1 << 20;
    let opts = rf_opts("huge");
    let Err(err) = train_rf(&cfg, &opts) else {
        panic!("a 2^20-clip micro-batch was accepted")
    };
    let err = err.to_string();
    assert!(
        err.contains("GiB of activations") && err.contains("train.micro_batch"),
        "{err}"
    );
    assert!(
        !fixture().dir.join("runs").join("huge-1").exists(),
        "no run folder is claimed"
    );
}
