//! Every TOML in `configs/` and `experiments/` resolves (`extends` included) to a complete run config: no unknown
//! keys, no missing keys, values in range. Also checks that a typo anywhere, `[model]` included, is rejected, that
//! the overlays are short and resolve to their base with the keys they change, and that `--set` overrides work.

use std::path::{Path, PathBuf};

use any4d_train::config::Override;
use any4d_train::config::resolve::{Files, resolve_text};
use any4d_train::rf_loop::RfRunConfig;
use any4d_train::run_config::RunConfig;
use any4d_train::vae_loop::VaeRunConfig;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn tomls(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries {
        let p = e.expect("readable directory entry").path();
        if p.is_dir() {
            tomls(&p, out);
        } else if p.extension().is_some_and(|x| x == "toml") && !p.ends_with("Cargo.toml") {
            // A Cargo.toml is a crate manifest (an experiment's standalone reproducer), not a run config.
            out.push(p);
        }
    }
}

/// Parses `text` (as if it were `path`, its `extends` chain read from disk) as the run config its tables announce:
/// `[vae]` → VAE, `[rf]` → RF.
fn parse_any(text: &str, path: &Path) -> Result<(), String> {
    let table = resolve_text(&Files, text, path).map_err(|e| e.to_string())?;
    RunConfig::from_table(table, path)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn every_config_and_experiment_toml_is_complete_and_known() {
    let mut files = Vec::new();
    tomls(&root().join("configs"), &mut files);
    tomls(&root().join("experiments"), &mut files);
    assert!(
        files.len() >= 7,
        "expected the presets of configs/vae and configs/rf, found {files:?}"
    );
    let errors: Vec<String> = files
        .iter()
        .filter_map(|f| parse_any(&std::fs::read_to_string(f).expect("readable"), f).err())
        .collect();
    assert!(errors.is_empty(), "bad configs:\n{}", errors.join("\n"));
}

#[test]
fn typos_and_omissions_are_rejected_in_every_table() {
    let vae = root().join("configs/vae/tiny.toml");
    let text = std::fs::read_to_string(&vae).expect("configs/vae/tiny.toml");
    assert!(parse_any(&text, &vae).is_ok());
    for (from, to, needle) in [
        ("width = 32", "widht = 32", "widht"), // [model.body]: the unknown `widht`
        ("width = 32\n", "width = 32\nwidth_mult = 2\n", "model.body"), // unknown [model.body] key
        ("width = 32\n", "width = 32\nwidth_mult = 2\n", "width_mult"),
        ("kl_weight = 1e-4\n", "", "kl_weight"),         // missing [model] key
        ("keep_last = 3", "keep_lats = 3", "keep_lats"), // [train]
        ("grad_clip = 1.0", "grad_clip = 0.0", "optim"), // out of range
        ("kind = \"framewise\"", "kind = \"framewize\"", "framewize"),
        ("train_frames = 4", "train_frames = 1", "vae.train_frames = 1"), // frame 0 alone
        ("train_frames = 4", "train_frames = -2", "train_frames"),        // not a count
        (
            "progress_every_secs = 5.0",
            "progress_every_secs = inf",
            "progress_every_secs",
        ), // no Duration holds it
        (
            "progress_every_secs = 5.0",
            "progress_every_secs = nan",
            "progress_every_secs",
        ),
        ("heads = 2", "heads = 0", "model.body.heads"), // zero-sized attention
        ("width = 32\n", "width = 1000000\n", "parameters"), // refused before any weight is allocated
        ("enc_blocks = 2", "enc_blocks = 1000000", "parameters"),
        ("offset_freqs = 10", "offset_freqs = 1000000000", "offset_freqs"),
        ("micro_batch = 4", "micro_batch = 4294967296", "micro_batch"),
        ("rec_average = \"batch\"", "rec_average = \"sum\"", "rec_average"),
        (
            "progress_every_secs = 5.0",
            "progress_every_secs = 5.0\nema_decay = 1.0",
            "train.ema_decay",
        ), // an average that never moves
        (
            "progress_every_secs = 5.0",
            "progress_every_secs = 5.0\nema_decay = -0.5",
            "train.ema_decay",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let err = parse_any(&text.replacen(from, to, 1), &vae).unwrap_err();
        assert!(
            err.contains(needle) && err.contains("tiny.toml"),
            "{from} → {to}: {err}"
        );
    }
    let dymesh = root().join("configs/vae/dymesh_paper.toml");
    let text = std::fs::read_to_string(&dymesh).expect("configs/vae/dymesh_paper.toml");
    assert!(parse_any(&text, &dymesh).is_ok());
    let err = parse_any(&text.replacen("train_frames = 0", "train_frames = 4", 1), &dymesh).unwrap_err();
    assert!(
        err.contains("vae.train_frames = 4") && err.contains("whole clips"),
        "{err}"
    );
    let rf = root().join("configs/rf/tiny.toml");
    let text = std::fs::read_to_string(&rf).expect("configs/rf/tiny.toml");
    assert!(parse_any(&text, &rf).is_ok());
    let err = parse_any(&text.replacen("k_max = 5", "k_max = 5\nk_min = 0", 1), &rf).unwrap_err();
    assert!(err.contains("k_min"), "{err}");
    let err = parse_any(&text.replacen("text_dropout = 0.1", "text_dropout = 1.5", 1), &rf).unwrap_err();
    assert!(err.contains("rf.text_dropout"), "{err}");
    let err = parse_any(&text.replacen("blocks = 2", "blocks = 100000000", 1), &rf).unwrap_err();
    assert!(err.contains("parameters"), "{err}");
}

#[test]
fn resolved_configs_round_trip() {
    let vae = root().join("configs/vae/paper.toml");
    let cfg = VaeRunConfig::load(&vae, &[]).unwrap();
    let again = VaeRunConfig::parse(&cfg.to_toml().unwrap(), Path::new("resolved.toml")).unwrap();
    assert_eq!(again.to_toml().unwrap(), cfg.to_toml().unwrap());
    assert_eq!(
        (cfg.train.batch_size, cfg.optim.lr, cfg.optim.beta2),
        (256, 1e-4, 0.999)
    );
    let rf = RfRunConfig::load(&root().join("configs/rf/paper.toml"), &[]).unwrap();
    assert_eq!(
        RfRunConfig::parse(&rf.to_toml().unwrap(), Path::new("r.toml")).unwrap(),
        rf
    );
    assert_eq!(
        (rf.train.batch_size, rf.optim.lr, rf.optim.beta2, rf.optim.weight_decay),
        (256, 2e-4, 0.99, 0.01)
    );
}

#[test]
fn overlays_are_short_and_resolve_to_their_base_with_the_changed_keys() {
    for (overlay, base) in [
        ("configs/rf/baseline_tiny.toml", "configs/rf/tiny.toml"),
        ("configs/rf/baseline_paper.toml", "configs/rf/paper.toml"),
    ] {
        let lines = std::fs::read_to_string(root().join(overlay)).unwrap().lines().count();
        assert!(
            lines <= 10,
            "{overlay} has {lines} lines: an overlay holds only what changes"
        );
        let over = RfRunConfig::load(&root().join(overlay), &[]).unwrap();
        let mut base = RfRunConfig::load(&root().join(base), &[]).unwrap();
        assert_ne!(over, base);
        base.model.conditioning = over.model.conditioning;
        assert_eq!(over, base, "{overlay} changes only model.conditioning");
    }
    let seq = VaeRunConfig::load(&root().join("configs/vae/dymesh_paper.toml"), &[]).unwrap();
    let frame = VaeRunConfig::load(&root().join("configs/vae/paper.toml"), &[]).unwrap();
    assert_eq!(seq.model.body().width, 256);
    assert_eq!(seq.optim, frame.optim, "the optimiser comes from the base");
    assert_eq!(seq.train.batch_size, 128);
}

/// The second-phase preset of experiments/2026-12-05-tau-finetune is `small.toml` with the uniform flow-time law, 1,000 steps and a constant 1e-4, and the
/// same network and caption encoder, so that `--init` accepts a small run.
#[test]
fn the_tail_preset_changes_only_the_tau_law_and_the_schedule() {
    use any4d_model::rectified_flow::TauSampler;
    use any4d_train::config::{Duration, LrSchedule};
    let tail = RfRunConfig::load(&root().join("experiments/2026-12-05-tau-finetune/small_tail.toml"), &[]).unwrap();
    let mut small = RfRunConfig::load(&root().join("configs/rf/small.toml"), &[]).unwrap();
    assert_eq!((&tail.model, &tail.text), (&small.model, &small.text));
    assert_ne!(small.rf.tau_sampler, TauSampler::Uniform);
    small.rf.tau_sampler = TauSampler::Uniform;
    small.train.duration = Duration::Steps(1000);
    small.optim.lr = 1e-4;
    small.optim.schedule = LrSchedule::Constant;
    assert_eq!(
        tail, small,
        "the preset changes only the flow-time law and the schedule"
    );
}

/// docs/method.md §4.10: the anchored preset is `small.toml` (which draws first-last training keyframes) plus the
/// anchor; the anchor is refused with a sampler that can leave a window without its ends, and with another
/// conditioning.
#[test]
fn the_anchor_preset_adds_the_anchor_and_the_anchor_needs_the_window_ends() {
    let path = root().join("configs/rf/anchored_small.toml");
    let anchored = RfRunConfig::load(&path, &[]).unwrap();
    let mut small = RfRunConfig::load(&root().join("configs/rf/small.toml"), &[]).unwrap();
    assert_ne!(anchored, small);
    assert_eq!(
        small.rf.kf_sampler, anchored.rf.kf_sampler,
        "both draw first-last keyframes"
    );
    small.model.anchor = anchored.model.anchor;
    assert_eq!(anchored, small, "the preset changes only model.anchor");
    let set = |s: &str| -> Vec<Override> { vec![s.parse().unwrap()] };
    let err = RfRunConfig::load(&path, &set("rf.kf_sampler=\"random\""))
        .unwrap_err()
        .to_string();
    assert!(err.contains("first_last") && err.contains("extrapolates"), "{err}");
    let err = RfRunConfig::load(&path, &set("model.conditioning=\"replace_noised\""))
        .unwrap_err()
        .to_string();
    assert!(err.contains("input_mask"), "{err}");
    let err = RfRunConfig::load(&path, &set("rf.k_max=1")).unwrap_err().to_string();
    assert!(err.contains("k_max"), "{err}");
}

#[test]
fn set_overrides_apply_after_extends_and_reject_unknown_keys() {
    let tiny = root().join("configs/rf/baseline_tiny.toml");
    let sets: Vec<Override> = ["rf.k_max=3", "rf.tau_sampler=cosmap", "train.duration={ steps = 7 }"]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
    let cfg = RfRunConfig::load(&tiny, &sets).unwrap();
    assert_eq!(cfg.rf.k_max, 3);
    assert_eq!(format!("{:?}", cfg.rf.tau_sampler), "Cosmap");
    assert_eq!(format!("{:?}", cfg.train.duration), "Steps(7)");
    assert_eq!(
        format!("{:?}", cfg.model.conditioning),
        "ReplaceNoised",
        "the overlay still applies"
    );
    let resolved = cfg.to_toml().unwrap();
    assert!(
        !resolved.contains("extends") && resolved.contains("k_max = 3"),
        "{resolved}"
    );
    let err = RfRunConfig::load(&tiny, &["rf.k_maxx=3".parse().unwrap()])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("unknown key `rf.k_maxx`") && err.contains("baseline_tiny.toml"),
        "{err}"
    );
    let err = RfRunConfig::load(&tiny, &["rf.k_max=\"three\"".parse().unwrap()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("rf.k_max"), "{err}");
    // The logit-normal τ sampler and the data-predicting network are keys like any other; bad values are refused.
    let sets: Vec<Override> = [
        "rf.tau_sampler={ logit_normal = { mean = -0.8, std = 0.8 } }",
        "model.prediction=data",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let cfg = RfRunConfig::load(&tiny, &sets).unwrap();
    assert_eq!(
        format!("{:?} {:?}", cfg.rf.tau_sampler, cfg.model.prediction),
        "LogitNormal { mean: -0.8, std: 0.8 } Data"
    );
    let bad = "rf.tau_sampler={ logit_normal = { mean = 0.0, std = -1.0 } }";
    let err = RfRunConfig::load(&tiny, &[bad.parse().unwrap()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("rf.tau_sampler") && err.contains("positive"), "{err}");
    let err = RfRunConfig::load(&tiny, &["model.prediction=noise".parse().unwrap()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("model.prediction") && err.contains("noise"), "{err}");
}

#[test]
fn run_folders_written_before_the_renames_still_load() {
    // VAE run folders once held the body's keys flat under [model], with `pad_keys = "Masked"`.
    let vae = root().join("configs/vae/tiny.toml");
    let text = std::fs::read_to_string(&vae).unwrap();
    let header = "\n# The encoder/decoder body both mesh VAEs share (model/src/mesh_vae.rs).\n[model.body]\n";
    assert!(text.contains(header));
    let flat = text.replace(header, "\n").replace("\"masked\"", "\"Masked\"");
    assert_eq!(
        VaeRunConfig::parse(&flat, &vae).unwrap(),
        VaeRunConfig::parse(&text, &vae).unwrap()
    );
    // Those folders predate `rec_average` and were trained with the batch form of (V1).
    let legacy = flat.replace("rec_average = \"batch\"", "");
    assert_ne!(legacy, flat);
    let migrated = VaeRunConfig::parse(&legacy, &vae).unwrap();
    assert_eq!(
        migrated.model.body().rec_average,
        any4d_model::mesh_vae::RecAverage::Batch
    );
    // RF run folders once named the keyframe conditioning `kf_mode`.
    let rf = root().join("configs/rf/tiny.toml");
    let text = std::fs::read_to_string(&rf).unwrap();
    let old = text.replace("conditioning = ", "kf_mode = ");
    assert_ne!(old, text);
    assert_eq!(
        RfRunConfig::parse(&old, &rf).unwrap(),
        RfRunConfig::parse(&text, &rf).unwrap()
    );
}

/// Stable-toolchain fuzzing of the config loader: 3,000 mutations of the tiny presets (numbers replaced by hostile
/// values, bytes flipped, lines dropped or duplicated) each parse to a config or a clean error, never a panic;
/// every accepted config also passes the model-size checks it was validated with.
/// Presets the config mutation tests start from.
const MUTATED_PRESETS: [&str; 5] = [
    "configs/vae/tiny.toml",
    "configs/rf/tiny.toml",
    "configs/vae/small.toml",
    "configs/rf/small.toml",
    "configs/bdlstm/small.toml",
];

/// Mutates preset lines (hostile values, bit flips, dropped and doubled lines) `rounds` times per preset, or until
/// `deadline`, and checks that the loader parses or refuses each with a message, never panics. Returns (inputs,
/// accepted).
fn mutate_presets(seed: u64, rounds: usize, deadline: Option<std::time::Instant>) -> (usize, usize) {
    use rand::{Rng, SeedableRng};
    let hostile = [
        "0",
        "-1",
        "1e308",
        "-1e308",
        "inf",
        "-inf",
        "nan",
        "1e6",
        "4294967296",
        "18446744073709551615",
        "0.0",
        "\"\"",
        "[]",
        "{}",
        "true",
    ];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (mut inputs, mut accepted) = (0, 0);
    let presets: Vec<(std::path::PathBuf, Vec<String>)> = MUTATED_PRESETS
        .iter()
        .map(|name| {
            let path = root().join(name);
            let text = std::fs::read_to_string(&path).unwrap();
            (path, text.lines().map(str::to_string).collect())
        })
        .collect();
    for round in 0.. {
        if round == rounds || deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            break;
        }
        for (path, lines) in &presets {
            let mut out = lines.clone();
            for _ in 0..rng.random_range(1..4) {
                let i = rng.random_range(0..out.len());
                match rng.random_range(0..4) {
                    0 => {
                        if let Some((key, _)) = out[i].split_once(" = ") {
                            out[i] = format!("{key} = {}", hostile[rng.random_range(0..hostile.len())]);
                        }
                    }
                    1 => {
                        let mut bytes = out[i].clone().into_bytes();
                        if !bytes.is_empty() {
                            let j = rng.random_range(0..bytes.len());
                            bytes[j] ^= 1 << rng.random_range(0..7);
                        }
                        out[i] = String::from_utf8_lossy(&bytes).into_owned();
                    }
                    2 => {
                        out.remove(i);
                    }
                    _ => {
                        let line = out[i].clone();
                        out.insert(i, line);
                    }
                }
                if out.is_empty() {
                    break;
                }
            }
            let mutated = out.join("\n");
            inputs += 1;
            match std::panic::catch_unwind(|| parse_any(&mutated, path)) {
                Ok(Ok(())) => accepted += 1,
                Ok(Err(e)) => assert!(!e.is_empty()),
                Err(_) => panic!("{}: the loader panicked on\n{mutated}", path.display()),
            }
        }
    }
    (inputs, accepted)
}

#[test]
fn mutated_configs_parse_or_give_a_clean_error() {
    let (inputs, accepted) = mutate_presets(11, 750, None);
    assert_eq!(inputs, 750 * MUTATED_PRESETS.len());
    assert!(accepted > 0, "some mutations (e.g. of comments) must still parse");
}

/// The long run of the config mutations (`ANY4D_FUZZ_SECS`, default 600; `ANY4D_FUZZ_SEED`), as fuzz/README.md
/// describes for the readers: `ANY4D_FUZZ_SECS=600 cargo test --workspace --test configs -- --ignored --nocapture`.
#[test]
#[ignore]
fn fuzz_configs_for_a_long_time() {
    let secs: u64 = std::env::var("ANY4D_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(600);
    let seed: u64 = std::env::var("ANY4D_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(secs);
    let (inputs, accepted) = mutate_presets(seed, usize::MAX, Some(deadline));
    println!("config: {inputs} inputs in {secs}s, {accepted} accepted, none panicked");
}

/// The frame-wise VAE presets that set every `[vae]` key themselves or through `extends`.
const VAE_PRESETS: [&str; 3] = [
    "configs/vae/paper.toml",
    "configs/vae/small.toml",
    "configs/vae/tiny.toml",
];

/// `--set` overrides from their text.
fn overrides(s: &[&str]) -> Vec<Override> {
    s.iter().map(|s| s.parse().unwrap()).collect()
}

#[test]
fn augmentation_keys_are_off_in_the_presets_set_by_override_and_checked_at_load() {
    let set = overrides;
    for preset in VAE_PRESETS {
        let cfg = VaeRunConfig::load(&root().join(preset), &[]).unwrap();
        assert!(cfg.vae.augment.is_off(), "{preset}");
        assert!(
            !cfg.to_toml().unwrap().contains("augment"),
            "{preset}: an off augmentation is not written"
        );
    }
    for preset in [
        "configs/rf/paper.toml",
        "configs/rf/small.toml",
        "configs/rf/baseline_paper.toml",
    ] {
        assert!(
            RfRunConfig::load(&root().join(preset), &[])
                .unwrap()
                .rf
                .augment
                .is_off(),
            "{preset}"
        );
    }
    let vae = root().join("configs/vae/tiny.toml");
    let on = VaeRunConfig::load(
        &vae,
        &set(&[
            "vae.augment.yaw_degrees=180.0",
            "vae.augment.mirror=0.5",
            "vae.augment.scale=[0.8, 1.25]",
        ]),
    )
    .unwrap();
    assert_eq!(on.vae.augment.yaw_degrees, 180.0);
    assert_eq!(on.vae.augment.scale, [0.8, 1.25]);
    let text = on.to_toml().unwrap();
    let back = VaeRunConfig::from_table(toml::from_str(&text).unwrap(), &vae).unwrap();
    assert_eq!(
        back.vae.augment, on.vae.augment,
        "the run folder's config keeps the keys"
    );
    for (bad, needle) in [
        ("vae.augment.scale=[1.5, 0.5]", "vae.augment.scale"),
        ("vae.augment.scale=[-1.0, 2.0]", "vae.augment.scale"),
        ("vae.augment.mirror=2.0", "vae.augment.mirror"),
        ("vae.augment.yaw_degrees=nan", "finite"),
        ("vae.augment.speed=[0.5, 2.0]", "vae.augment.speed"),
        ("vae.augment.motion=[1.0, 5.0]", "vae.augment.motion"),
        ("vae.augment.sped=[0.5, 1.0]", "sped"),
    ] {
        let err = VaeRunConfig::load(&vae, &set(&[bad])).unwrap_err().to_string();
        assert!(err.contains(needle), "{bad}: {err}");
    }
    let rf = root().join("configs/rf/tiny.toml");
    let err = RfRunConfig::load(
        &rf,
        &set(&["rf.latent_cache=\"memory\"", "rf.augment.yaw_degrees=90.0"]),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("per_batch"), "{err}");
    let ok = RfRunConfig::load(&rf, &set(&["rf.latent_cache=\"per_batch\"", "rf.augment.reverse=0.5"])).unwrap();
    assert_eq!(ok.rf.augment.reverse, 0.5);
    // Latent files hold no augmentation and no scene features.
    for extra in ["rf.augment.reverse=0.5", "model.scene.global=true"] {
        let err = RfRunConfig::load(&rf, &set(&["rf.latent_cache=\"disk\"", extra]))
            .unwrap_err()
            .to_string();
        assert!(err.contains("latent_cache"), "{extra}: {err}");
    }
    assert!(RfRunConfig::load(&rf, &set(&["rf.latent_cache=\"disk\""])).is_ok());
}

/// `vae.stats_windows` caps the windows latent statistics are computed from: 0 (all windows) in every preset, kept
/// in the run folder's config, absent in run folders written before it (read as 0); the subset is evenly strided
/// and deterministic.
#[test]
fn latent_statistics_window_cap() {
    use any4d_train::vae_loop::stats_subset;
    let set = overrides;
    for preset in VAE_PRESETS {
        let cfg = VaeRunConfig::load(&root().join(preset), &[]).unwrap();
        assert_eq!((cfg.vae.stats_windows, cfg.vae.valid_windows), (0, 0), "{preset}");
    }
    let vae = root().join("configs/vae/tiny.toml");
    let on = VaeRunConfig::load(&vae, &set(&["vae.stats_windows=3", "vae.valid_windows=2"])).unwrap();
    assert_eq!(on.vae.valid_windows, 2);
    let text = on.to_toml().unwrap();
    let back = VaeRunConfig::from_table(toml::from_str(&text).unwrap(), &vae).unwrap();
    assert_eq!(back.vae.stats_windows, 3);
    let old = text.replace("stats_windows = 3\n", "");
    assert_ne!(old, text);
    let back = VaeRunConfig::from_table(toml::from_str(&old).unwrap(), &vae).unwrap();
    assert_eq!(back.vae.stats_windows, 0);
    let err = VaeRunConfig::load(&vae, &set(&["vae.stats_windows=-1"]))
        .unwrap_err()
        .to_string();
    assert!(err.contains("stats_windows"), "{err}");
    let train: Vec<usize> = (100..110).collect();
    assert_eq!(stats_subset(&train, 0), train);
    assert_eq!(stats_subset(&train, 10), train);
    assert_eq!(stats_subset(&train, 3), [100, 103, 106]);
    assert_eq!(stats_subset(&train, 1), [100]);
}
