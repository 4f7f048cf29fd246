//! The BD-LSTM as published (docs/method.md §5.3, ACAP variant) on a single-topology store: a short run lowers
//! (B3) and records its reference mesh and scaling, validation is reproduced by the loaded run, the run completes
//! clips as the `bdlstm_acap` row from the keyframes alone, and the refusals: a store of several topologies
//! (naming two clips that differ, no run folder left), `--vae` with the ACAP variant, each variant's run given to
//! the other's flag, a clip of another topology, a corrupt `acap.json`.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use any4d_data::store::{Split, Store, write_synth_with};
use any4d_data::synth::{ShapeFamily, SynthConfig};
use any4d_eval::methods::{MethodKind, hide_non_keyframes};
use any4d_train::bdlstm::{resume_bdlstm, train_bdlstm};
use any4d_train::bdlstm_acap::{ACAP_FILE, AcapObjective, AcapRecord, load_acap_bdlstm_run};
use any4d_train::bdlstm_loop::{BDLSTM_TERMS, BdlstmRunConfig, BdlstmRunOptions, BdlstmVariant, load_bdlstm_run};
use any4d_train::config::Duration;
use any4d_train::evaluate::{LearnedRuns, SamplingSetup, build_methods};
use any4d_train::loop_common::{Objective, Outcome};
use any4d_train::pack::{Precision as PackPrecision, pack_run};
use any4d_train::run_folder::{CONFIG_FILE, METRICS_FILE, VALID_FILE, read_table};
use common::{bdlstm_preset, copy_dir, cpu, params, root, run_options, serial};

struct Fixture {
    dir: tempfile::TempDir,
    store: PathBuf,
}

/// 12 clips of 6 frames, all animating one humanoid of 256–512 vertices.
fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("one-body");
        let synth = SynthConfig {
            clips: 12,
            seed: 5,
            frames: 6,
            min_vertices: 256,
            max_vertices: 512,
            body: Some(ShapeFamily::Humanoid),
            family: Default::default(),
            scenes: false,
        };
        write_synth_with(&synth, &store, 32, None).expect("single-topology store");
        Fixture { dir, store }
    })
}

fn opts(store: &Path, name: &str) -> BdlstmRunOptions {
    BdlstmRunOptions {
        run: run_options(store, fixture().dir.path(), name),
        vae_run: None,
    }
}

/// configs/bdlstm/acap_tiny.toml for `steps` steps of 4 clips.
fn tiny(steps: u64) -> BdlstmRunConfig {
    let cfg = bdlstm_preset("acap_tiny.toml", steps);
    assert_eq!(cfg.model.variant, BdlstmVariant::Acap);
    cfg
}

#[test]
fn tiny_acap_bdlstm_trains_and_completes_from_keyframes_alone() {
    let _g = serial();
    let steps = 60;
    let cfg = tiny(steps);
    let f = fixture();
    let (run, outcome) = train_bdlstm(&cfg, &opts(&f.store, "acap")).expect("tiny ACAP run");
    assert!(matches!(outcome, Outcome::Finished { steps: 60, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    let total = BDLSTM_TERMS.len();
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[total]).sum::<f64>() / rows.len() as f64;
    let (first, last) = (mean(&t.rows[..10]), mean(&t.rows[t.rows.len() - 10..]));
    assert!(last < 0.8 * first, "loss {first} → {last}");

    // acap.json holds frame 0 of the first TRAIN clip and a per-vertex scaling.
    let record = AcapRecord::read(run.root()).unwrap();
    let store = Store::open(&f.store).unwrap();
    let first_train = store.get(store.indices(Split::Train)[0]).unwrap().clip;
    assert_eq!(record.reference_clip, first_train.id);
    assert_eq!(record.reference, first_train.vertices[..first_train.n_vertices]);
    assert_eq!(record.scaling.mid.len(), first_train.n_vertices);

    // The loaded run reproduces the logged validation.
    let dev = cpu();
    let loaded = load_acap_bdlstm_run(run.root(), &dev).unwrap();
    assert_eq!((loaded.step, &loaded.config), (steps, &cfg));
    let objective = AcapObjective::new(&cfg, &f.store, Some(record.clone())).unwrap();
    let values = objective
        .validate(&loaded.model, &dev, steps)
        .unwrap()
        .expect("VAL clips");
    let (_, logged) = read_table(&run.path(VALID_FILE)).unwrap().rows.pop().unwrap();
    for (v, l) in values.iter().zip(&logged) {
        assert!((v - l).abs() <= 1e-5 * l.abs().max(1.0), "{values:?} vs {logged:?}");
    }

    // As an evaluation row: keyframes exactly as given, every frame finite, the same output for the same seed
    // whatever the hidden frames hold.
    let runs = LearnedRuns {
        bdlstm_acap: Some(run.root().to_path_buf()),
        ..LearnedRuns::default()
    };
    let built = build_methods(&[MethodKind::BdlstmAcap], &runs, SamplingSetup::default(), &dev).unwrap();
    let method = &built.methods[0];
    let clip = store.get(store.indices(Split::Val)[0]).unwrap().clip;
    let (n, keys) = (clip.n_vertices, [0, 2, 5]);
    let visible = hide_non_keyframes(&clip, &keys);
    let a = method.complete(&visible, &keys, "", 7).unwrap();
    assert_eq!(a.len(), clip.frames * n);
    assert!(a.iter().flatten().all(|v| v.is_finite()));
    for k in keys {
        assert_eq!(a[k * n..(k + 1) * n], clip.vertices[k * n..(k + 1) * n], "keyframe {k}");
    }
    assert_ne!(
        a[n..2 * n],
        clip.vertices[n..2 * n],
        "frame 1 copied from the ground truth"
    );
    assert_eq!(a, method.complete(&clip, &keys, "", 7).unwrap());
    let err = method.complete(&visible, &[0, 2], "", 7).unwrap_err().to_string();
    assert!(err.contains("must be keyframes"), "{err}");

    // A clip of another topology is refused by name.
    let mut other = clip.clone();
    other.faces.swap(0, 1);
    let err = method.complete(&other, &keys, "", 7).unwrap_err().to_string();
    assert!(
        err.contains("one fixed topology") && err.contains(&record.reference_clip),
        "{err}"
    );

    // Each variant's run given to the other's flag.
    let err = load_bdlstm_run(run.root(), &dev).err().unwrap().to_string();
    assert!(err.contains("--bdlstm-acap"), "{err}");
    let latent_dir = f.dir.path().join("latent-config");
    std::fs::create_dir_all(&latent_dir).unwrap();
    let latent = BdlstmRunConfig::load(&root().join("configs/bdlstm/tiny.toml"), &[]).unwrap();
    std::fs::write(latent_dir.join(CONFIG_FILE), latent.to_toml().unwrap()).unwrap();
    let err = load_acap_bdlstm_run(&latent_dir, &dev).err().unwrap().to_string();
    assert!(err.contains("--bdlstm RUN"), "{err}");

    // `model pack` keeps the reference and scaling: the packed run completes the same.
    let out = tempfile::tempdir().unwrap();
    let packed = pack_run(run.root(), &out.path().join("bd"), PackPrecision::Full, None, &dev).unwrap();
    assert_eq!((packed.kind, packed.step), ("BD-LSTM (ACAP)", steps));
    let reloaded = load_acap_bdlstm_run(&out.path().join("bd"), &dev).unwrap();
    assert_eq!(params(&reloaded.model), params(&loaded.model));
    let runs = LearnedRuns {
        bdlstm_acap: Some(out.path().join("bd")),
        ..LearnedRuns::default()
    };
    let built = build_methods(&[MethodKind::BdlstmAcap], &runs, SamplingSetup::default(), &dev).unwrap();
    assert_eq!(a, built.methods[0].complete(&visible, &keys, "", 7).unwrap());

    // A corrupt acap.json: a clear error, not a panic.
    let broken = f.dir.path().join("broken-run");
    copy_dir(run.root(), &broken);
    let mut bad = record;
    bad.scaling.mid.pop();
    std::fs::write(broken.join(ACAP_FILE), serde_json::to_vec(&bad).unwrap()).unwrap();
    let err = load_acap_bdlstm_run(&broken, &dev).err().unwrap().to_string();
    assert!(err.contains("scaling rows"), "{err}");
    std::fs::write(broken.join(ACAP_FILE), b"{\"reference\": [[0, 0").unwrap();
    let err = load_acap_bdlstm_run(&broken, &dev).err().unwrap().to_string();
    assert!(err.contains(ACAP_FILE), "{err}");
}

#[test]
fn acap_setups_that_cannot_work_are_refused_before_a_run_folder_exists() {
    let _g = serial();
    let f = fixture();
    // A store of several topologies: the error names two clips that differ.
    let mixed = f.dir.path().join("mixed");
    let synth = SynthConfig {
        clips: 6,
        seed: 5,
        frames: 6,
        min_vertices: 256,
        max_vertices: 600,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    write_synth_with(&synth, &mixed, 32, None).unwrap();
    let o = opts(&mixed, "mixed");
    let err = train_bdlstm(&tiny(2), &o).err().unwrap().to_string();
    assert!(err.contains("one fixed topology"), "{err}");
    assert_eq!(err.matches("synth-").count(), 2, "names two clips: {err}");
    assert!(!o.run.runs_dir.join("mixed-1").exists(), "a run folder was claimed");

    // --vae with the ACAP variant.
    let mut o = opts(&f.store, "with-vae");
    o.vae_run = Some(f.dir.path().join("some-vae"));
    let err = train_bdlstm(&tiny(2), &o).err().unwrap().to_string();
    assert!(err.contains("drop --vae"), "{err}");

    // Bad ACAP keys name the field.
    let path = root().join("configs/bdlstm/acap_tiny.toml");
    for (key, value) in [
        ("model.conv_layers", "0"),
        ("model.conv_layers", "65"),
        ("model.variant", "\"mesh\""),
        ("bdlstm.acap_scaling", "\"per_frame\""),
    ] {
        let set = format!("{key}={value}").parse().unwrap();
        let err = BdlstmRunConfig::load(&path, &[set]).unwrap_err().to_string();
        let field = key.rsplit('.').next().unwrap();
        assert!(err.contains(field), "{key} = {value}: {err}");
    }
}

#[test]
fn acap_resume_reuses_the_recorded_reference_and_equals_straight_training() {
    let _g = serial();
    let f = fixture();
    let mut cfg = tiny(4);
    cfg.train.checkpoint_every = 2;
    let (straight, _) = train_bdlstm(&cfg, &opts(&f.store, "straight")).unwrap();
    // The same run stopped after 2 steps and resumed to 4.
    let mut first = cfg.clone();
    first.train.duration = Duration::Steps(2);
    let (split, _) = train_bdlstm(&first, &opts(&f.store, "split")).unwrap();
    let config = split.path(CONFIG_FILE);
    std::fs::write(&config, cfg.to_toml().unwrap()).unwrap();
    let outcome = resume_bdlstm(split.root(), None, &opts(&f.store, "unused")).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 4, .. }), "{outcome:?}");
    let dev = cpu();
    let (a, b) = (
        load_acap_bdlstm_run(straight.root(), &dev).unwrap(),
        load_acap_bdlstm_run(split.root(), &dev).unwrap(),
    );
    assert_eq!(a.record, b.record);
    assert_eq!(
        params(&a.model),
        params(&b.model),
        "resumed ACAP BD-LSTM differs from straight training"
    );
    // --vae does not apply to a resumed ACAP run either.
    let mut with_vae = opts(&f.store, "unused");
    with_vae.vae_run = Some(f.dir.path().join("some-vae"));
    let err = resume_bdlstm(split.root(), None, &with_vae).err().unwrap().to_string();
    assert!(err.contains("drop --vae"), "{err}");
}
