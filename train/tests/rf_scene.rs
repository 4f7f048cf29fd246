//! Scene conditioning in the RF loop (docs/method.md §4.12): batches carry each clip's occupancy grid (S1) and its
//! anchors' offsets (S2) at the batch's keyframes only, as (S4) lays them out; a clip without a scene is told nothing;
//! a network that reads the scene trains, and its saved parameters reproduce the logged validation loss. One tiny
//! VAE run on procedural scene clips is shared by the tests.

mod common;

use std::sync::OnceLock;

use any4d_data::scene::features::clip_scene_features;
use any4d_data::store::Store;
use any4d_model::interop::Names;
use any4d_model::mmdit::{LOCAL_CHANNELS, SceneConditioning};
use any4d_model::text::scratch::ScratchTokenizer;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::config::Duration;
use any4d_train::interop::{MODEL_SAFETENSORS, export_run, import_file};
use any4d_train::loop_common::{Objective, Outcome};
use any4d_train::rf_loop::{
    LatentCache, LatentDraw, RfObjective, RfRunConfig, RfRunOptions, Subset, TextDropout, train_rf,
};
use any4d_train::run_folder::{RunFolder, SAMPLES_FILE, VALID_FILE, read_table};
use any4d_train::runs::{load_rf_run, load_vae_run};
use burn::prelude::Device;
use common::{VaeFixture, root, run_options, serial, tiny_vae, vae_fixture_in};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A store of 10 procedural clips in scenes and a 6-step VAE on it.
fn fixture() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture_in(1, tiny_vae(6), true))
}

/// configs/rf/tiny.toml for the fixture, reading both scene parts on an 8 × 4 × 8 grid of 0.5 (4 context tokens).
fn scene_rf(steps: u64) -> RfRunConfig {
    let mut cfg = RfRunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).expect("configs/rf/tiny.toml");
    cfg.model.frames = 4;
    cfg.model.scene = SceneConditioning {
        global: true,
        local: true,
        grid: [8, 4, 8],
        cell: 0.5,
        patch: 4,
    };
    cfg.rf.k_max = 3;
    cfg.rf.latent = LatentDraw::Mean;
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 4;
    cfg.train.checkpoint_every = steps;
    cfg.train.valid_every = steps;
    cfg.rf.valid_sample_every = 0;
    cfg
}

fn cpu() -> Device {
    device(Backend::Flex, Precision::F32).expect("flex device")
}

fn objective(cfg: &RfRunConfig, dev: &Device) -> (RfObjective, usize) {
    let f = fixture();
    let vae = load_vae_run(&f.vae_run, dev).unwrap();
    let store = Store::open(&f.store).unwrap();
    let captions: Vec<String> = (0..store.len()).map(|i| store.get(i).unwrap().clip.caption).collect();
    let tokenizer = ScratchTokenizer::train(&captions, cfg.text.vocab_size).unwrap();
    let vocab = tokenizer.vocab_size();
    (
        RfObjective::new(cfg, &f.store, None, &vae, tokenizer, dev).unwrap(),
        vocab,
    )
}

fn values<const D: usize>(t: burn::prelude::Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap()
}

/// Each clip's grid row is its (S1) around frame 0; at a keyframe its slot holds the anchors' (S2) offsets and the
/// flag 1, at any other frame zeros (m = 1 is a keyframe). The anchors are the store's first P FPS points, the
/// VAE's tokens. The same with latents cached in memory and encoded per batch.
#[test]
fn batches_carry_each_clips_grid_and_its_keyframe_offsets() {
    let _g = serial();
    let dev = cpu();
    for cache in [LatentCache::Memory, LatentCache::PerBatch] {
        let mut cfg = scene_rf(1);
        cfg.rf.latent_cache = cache;
        check_batches(&cfg, &dev);
    }
    let cfg = scene_rf(1);
    let positions = [0usize, 1, 2];
    // The same objective without the scene keys tells the network nothing.
    let mut plain = cfg.clone();
    plain.model.scene = SceneConditioning::default();
    let (obj, vocab) = objective(&plain, &dev);
    let model = plain.model_config(vocab).init(&dev);
    let step = obj
        .batcher()
        .batch(
            &model,
            Subset::Train,
            &positions,
            &mut ChaCha8Rng::seed_from_u64(0),
            TextDropout::Off,
            &dev,
        )
        .unwrap();
    assert!(step.batch.scene.is_none());
}

/// The batch checks of [`batches_carry_each_clips_grid_and_its_keyframe_offsets`] under `cfg`.
fn check_batches(cfg: &RfRunConfig, dev: &Device) {
    let dev = dev.clone();
    let (obj, vocab) = objective(cfg, &dev);
    let model = cfg.model_config(vocab).init(&dev);
    let batcher = obj.batcher();
    let store = batcher.store();
    let (p, t, cells) = (batcher.tokens(), cfg.model.frames, cfg.model.scene.grid_cells());
    let positions = [0usize, 1, 2];
    let mut keyframes_seen = 0;
    for seed in 0..6 {
        let step = batcher
            .batch(
                &model,
                Subset::Train,
                &positions,
                &mut ChaCha8Rng::seed_from_u64(seed),
                TextDropout::Off,
                &dev,
            )
            .unwrap();
        let scene = step.batch.scene.expect("a scene-aware config gives its batches scenes");
        let (grid, slots, mask) = (values(scene.grid), values(scene.keyframes), values(step.batch.mask));
        assert_eq!((grid.len(), slots.len()), (3 * cells, 3 * p * t * LOCAL_CHANNELS));
        for (i, &pos) in positions.iter().enumerate() {
            let item = store.get(batcher.train_indices()[pos]).unwrap();
            let s = item.scene.as_ref().expect("the fixture's clips have scenes");
            let want = clip_scene_features(&item.clip, s, &item.fps[..p], &cfg.model.scene.grid_spec()).unwrap();
            assert_eq!(
                &grid[i * cells..(i + 1) * cells],
                want.grid.as_slice(),
                "grid of clip {i}"
            );
            assert!(
                want.grid.contains(&1.0),
                "clip {i}'s scene occupies no cell: the check could not fail"
            );
            for f in 0..t {
                let key = mask[i * t + f] == 1.0;
                keyframes_seen += usize::from(key);
                for tok in 0..p {
                    let at = ((i * p + tok) * t + f) * LOCAL_CHANNELS;
                    let got = &slots[at..at + LOCAL_CHANNELS];
                    let off = &want.offsets[(f * p + tok) * 3..][..3];
                    let expected = if key { [off[0], off[1], off[2], 1.0] } else { [0.0; 4] };
                    assert_eq!(got, expected, "clip {i}, frame {f}, token {tok}");
                }
            }
        }
    }
    assert!(
        keyframes_seen > 0,
        "no keyframe was drawn, so the offsets were never checked"
    );
}

/// The scene RF of 12 steps, trained once per test process.
fn trained() -> &'static RunFolder {
    static RUN: OnceLock<RunFolder> = OnceLock::new();
    RUN.get_or_init(|| {
        let f = fixture();
        let opts = RfRunOptions {
            run: run_options(&f.store, &f.dir, "rf-scene"),
            vae_run: Some(f.vae_run.clone()),
            init: None,
            latents: None,
        };
        // Validation samples at the end too: 2 VAL clips completed in their scenes on a 4-point grid.
        let mut cfg = scene_rf(12);
        cfg.rf.valid_sample_every = 12;
        cfg.rf.valid_sample_clips = 2;
        cfg.rf.valid_sample_grid = 4;
        let (run, outcome) = train_rf(&cfg, &opts).expect("scene RF run");
        let samples = read_table(&run.root().join(SAMPLES_FILE)).expect("samples.csv");
        assert!(
            samples.rows.iter().all(|(_, v)| v.iter().all(|x| x.is_finite())),
            "{:?}",
            samples.rows
        );
        assert!(matches!(outcome, Outcome::Finished { steps: 12, .. }), "{outcome:?}");
        run
    })
}

/// A network reading both parts trains; loaded from its run folder it reproduces the logged validation loss, so the
/// scene parameters are saved and the validation batches carry the scenes they were trained with (without them the
/// loss differs); it exports and imports under any4d's names and is refused under AnimateAnyMesh's.
#[test]
fn a_scene_aware_rf_trains_and_its_run_reproduces_its_validation_loss() {
    let _g = serial();
    let f = fixture();
    let mut cfg = scene_rf(12);
    (
        cfg.rf.valid_sample_every,
        cfg.rf.valid_sample_clips,
        cfg.rf.valid_sample_grid,
    ) = (12, 2, 4);
    let run = trained();
    let dev = cpu();
    let loaded = load_rf_run(run.root(), &dev).unwrap();
    assert_eq!(loaded.config.model.scene, cfg.model.scene);
    assert_eq!(loaded.model.mmdit.scene(), &cfg.model.scene);
    let vae = loaded.load_vae(&dev).unwrap();
    let tokenizer = ScratchTokenizer::load(run.root()).unwrap();
    let obj = RfObjective::new(&cfg, &f.store, None, &vae, tokenizer, &dev).unwrap();
    let got = obj
        .validate(&loaded.model, &dev, loaded.step)
        .unwrap()
        .expect("VAL clips");
    let table = read_table(&run.root().join(VALID_FILE)).unwrap();
    let (_, logged) = table.rows.last().expect("a validation row");
    let rel = (got[2] - logged[2]).abs() / logged[2];
    assert!(rel < 1e-6, "validation loss {} vs logged {}", got[2], logged[2]);
    // The scene matters to the trained network at that precision: told nothing, it scores otherwise.
    let mut blind = cfg.clone();
    blind.model.scene = SceneConditioning::default();
    let tokenizer = ScratchTokenizer::load(run.root()).unwrap();
    let obj = RfObjective::new(&blind, &f.store, None, &vae, tokenizer, &dev).unwrap();
    let without = obj
        .validate(&loaded.model, &dev, loaded.step)
        .unwrap()
        .expect("VAL clips");
    let rel = (without[2] - logged[2]).abs() / logged[2];
    assert!(
        rel > 1e-5,
        "the scene changes the validation loss by {rel} only: the check above could not fail"
    );
    // Exported under any4d's names it imports whole; AnimateAnyMesh has no scene parts to name, so that is refused
    // and nothing is written.
    let out = tempfile::tempdir().unwrap();
    let export = out.path().join("export");
    export_run(run.root(), &export, Names::Any4d, &dev).unwrap();
    import_file(
        &export.join(MODEL_SAFETENSORS),
        &out.path().join("back"),
        None,
        None,
        &dev,
    )
    .unwrap();
    let back = load_rf_run(&out.path().join("back"), &dev).unwrap();
    assert_eq!(common::params(&back.model), common::params(&loaded.model));
    let refused = out.path().join("aam");
    let e = export_run(run.root(), &refused, Names::AnimateAnyMesh, &dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("scene-aware") && !refused.exists(), "{e}");
}

/// `any4d complete` with a scene-aware RF: the scene (in the keyframes' coordinates) changes the completion of one
/// window, and a longer clip, which rolls out window by window without it, is refused rather than completed blind.
#[test]
fn complete_tells_a_scene_aware_rf_the_scene_of_one_window_only() {
    use any4d_train::complete::{CompleteOptions, KeyMeshes, complete};
    use any4d_train::evaluate::{SamplingSetup, keyframe_method};
    let _g = serial();
    let run = trained();
    let dev = cpu();
    let model = keyframe_method(run.root(), SamplingSetup::default(), false, &dev).unwrap();
    assert!(model.reads_scene);
    let store = Store::open(&fixture().store).unwrap();
    let item = store.get(0).unwrap();
    let clip = &item.clip;
    let keys = KeyMeshes {
        id: clip.id.clone(),
        n_vertices: clip.n_vertices,
        faces: clip.faces.clone(),
        keys: vec![(0, clip.frame(0).to_vec()), (3, clip.frame(3).to_vec())],
        clip_frames: Some(clip.frames),
        clip_caption: None,
    };
    let opts = |scene, frames| CompleteOptions {
        frames,
        caption: String::new(),
        seed: 1,
        samples: 1,
        scene,
    };
    let run_with = |scene| {
        complete(
            &keys,
            model.method.as_ref(),
            model.window,
            model.tokens,
            &opts(scene, 4),
        )
        .unwrap()
    };
    let (blind, seen) = (run_with(None), run_with(item.scene.clone()));
    let gap = blind[0]
        .vertices
        .iter()
        .zip(&seen[0].vertices)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0f32, f32::max);
    assert!(gap > 1e-6, "the scene did not change the completion");
    let e = complete(
        &keys,
        model.method.as_ref(),
        model.window,
        model.tokens,
        &opts(item.scene.clone(), 7),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("scene") && e.contains("window"), "{e}");
}
