//! The RF's latent files (`rf.latent_cache = "disk"`, docs/training.md "Latents on disk"): shards encoded one at a
//! time (as separate processes would) are reused by a run, hold the latents the in-memory cache holds and train the
//! same; a file that is missing, truncated, of another VAE or of another shard content is encoded again; a value that
//! is not finite is an error naming the file, the clip and the field; a shard number past the store's is refused.

mod common;

use std::path::Path;
use std::sync::OnceLock;

use any4d_data::store::{Split, Store};
use any4d_model::text::scratch::ScratchTokenizer;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::config::Duration;
use any4d_train::loop_common::Outcome;
use any4d_train::rf_loop::{
    DiskLatents, Encoder, FileState, LATENTS_DIR, LatentCache, LatentDraw, RfObjective, RfRunConfig, RfRunOptions,
    Subset, TextDropout, encode_store_latents, resume_rf, shard_file, train_rf,
};
use any4d_train::run_folder::LOG_FILE;
use any4d_train::runs::load_vae_run;
use burn::prelude::Device;
use common::{VaeFixture, root, run_options, serial, sharded_synth_store, vae_fixture};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn fixture() -> &'static VaeFixture {
    static FIXTURE: OnceLock<VaeFixture> = OnceLock::new();
    FIXTURE.get_or_init(|| vae_fixture(1))
}

fn cpu() -> Device {
    device(Backend::Flex, Precision::F32).expect("flex device")
}

/// configs/rf/tiny.toml for the fixture's 4-frame clips, posterior means as targets (no ξ draw to compare).
fn tiny_rf(cache: LatentCache) -> RfRunConfig {
    let mut cfg = RfRunConfig::load(&root().join("configs/rf/tiny.toml"), &[]).expect("configs/rf/tiny.toml");
    cfg.model.frames = 4;
    cfg.rf.k_max = 3;
    cfg.rf.latent = LatentDraw::Mean;
    cfg.rf.latent_cache = cache;
    cfg.rf.valid_sample_every = 0;
    cfg.train.duration = Duration::Steps(2);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 4;
    cfg
}

fn objective(cfg: &RfRunConfig, store: &Path, latents: Option<&Path>, dev: &Device) -> (RfObjective, usize) {
    let vae = load_vae_run(&fixture().vae_run, dev).unwrap();
    let opened = Store::open(store).unwrap();
    let captions = opened.captions(&opened.indices(Split::Train)).unwrap();
    let tokenizer = ScratchTokenizer::train(&captions, cfg.text.vocab_size).unwrap();
    let vocab = tokenizer.vocab_size();
    (
        RfObjective::new(cfg, store, latents, &vae, tokenizer, dev).unwrap(),
        vocab,
    )
}

fn values<const D: usize>(t: burn::prelude::Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap()
}

/// Three shards encoded one by one are current for a second call and for the run, which encodes nothing; the run's
/// batches equal those of the latents cached in memory (same positions, same draws) to float precision.
#[test]
fn shards_encoded_apart_are_reused_and_batch_like_the_memory_cache() {
    let _g = serial();
    let f = fixture();
    let dev = cpu();
    let store = sharded_synth_store(&f.dir, 1, 3);
    let dir = f.dir.join("latents-sharded");
    for k in 0..3 {
        let mut seen = Vec::new();
        encode_store_latents(&f.vae_run, &store, &dir, Some(k), 4, Backend::Flex, &mut |s, st| {
            seen.push((s, st.clone()))
        })
        .unwrap();
        assert_eq!(seen, vec![(k, FileState::Missing)]);
        assert!(shard_file(&dir, k).is_file());
    }
    let mut again = Vec::new();
    encode_store_latents(&f.vae_run, &store, &dir, None, 4, Backend::Flex, &mut |s, st| {
        again.push((s, st.clone()))
    })
    .unwrap();
    assert_eq!(again, (0..3).map(|k| (k, FileState::Current)).collect::<Vec<_>>());
    let err = encode_store_latents(&f.vae_run, &store, &dir, Some(3), 4, Backend::Flex, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("--shard 3") && err.contains("3 shard"), "{err}");

    let (disk, vocab) = objective(&tiny_rf(LatentCache::Disk), &store, Some(&dir), &dev);
    let note = disk.batcher().latent_files_note().unwrap();
    assert!(note.contains("3 shard(s) reused, 0 encoded"), "{note}");
    let (memory, _) = objective(&tiny_rf(LatentCache::Memory), &store, None, &dev);
    assert_eq!(memory.batcher().latent_files_note(), None);
    let cfg = tiny_rf(LatentCache::Disk);
    let model = cfg.model_config(vocab).init(&dev);
    for (subset, positions) in [(Subset::Train, vec![0usize, 3, 5, 1]), (Subset::Valid, vec![0usize])] {
        let step = |obj: &RfObjective| {
            obj.batcher()
                .batch(
                    &model,
                    subset,
                    &positions,
                    &mut ChaCha8Rng::seed_from_u64(7),
                    TextDropout::Off,
                    &dev,
                )
                .unwrap()
        };
        let (a, b) = (step(&disk), step(&memory));
        let (za, zb) = (values(a.batch.z), values(b.batch.z));
        assert_eq!(za.len(), zb.len());
        let worst = za.iter().zip(&zb).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
        assert!(worst < 1e-4, "{subset:?}: disk and memory latents differ by {worst}");
        assert_eq!(values(a.batch.mask), values(b.batch.mask));
        assert_eq!(values(a.eps), values(b.eps));
    }
}

/// A missing, truncated, foreign or re-imported shard's file is encoded again; a NaN in a record is an error naming
/// the file, the clip and the field; a header claiming 2⁶⁴ − 1 clips is only stale (nothing allocated from it).
#[test]
fn stale_files_are_encoded_again_and_bad_values_are_named() {
    let _g = serial();
    let f = fixture();
    let dev = cpu();
    let vae = load_vae_run(&f.vae_run, &dev).unwrap();
    let store = Store::open(&f.store).unwrap();
    let dir = f.dir.join("latents-one-file");
    let encoder = Encoder::new(&vae, 4, 1, &dev).unwrap();
    let prepare = || {
        let mut states = Vec::new();
        let disk = DiskLatents::prepare(&dir, &store, &encoder, &mut |_, s| states.push(s.clone())).unwrap();
        (disk, states.pop().unwrap())
    };
    assert_eq!(prepare().1, FileState::Missing);
    assert_eq!(prepare().1, FileState::Current);
    let file = shard_file(&dir, 0);
    let good = std::fs::read(&file).unwrap();
    let stale_after = |bytes: &[u8], why: &str| {
        std::fs::write(&file, bytes).unwrap();
        match prepare().1 {
            FileState::Stale(reason) => assert!(reason.contains(why), "{why}: {reason}"),
            other => panic!("{why}: {other:?}"),
        }
        assert_eq!(
            std::fs::read(&file).unwrap(),
            good,
            "{why}: encoded again to the same bytes"
        );
    };
    stale_after(&good[..good.len() - 5], "truncated");
    stale_after(&good[..20], "shorter than");
    let mut magic = good.clone();
    magic[0] = b'X';
    stale_after(&magic, "magic");
    let mut foreign = good.clone();
    foreign[40] ^= 1; // the VAE fingerprint
    stale_after(&foreign, "another VAE");
    let mut other_shard = good.clone();
    other_shard[32] ^= 1; // the shard checksum
    stale_after(&other_shard, "re-imported");
    let mut huge = good.clone();
    huge[24..32].copy_from_slice(&u64::MAX.to_le_bytes());
    stale_after(&huge, "clips");

    // The header and length are checked when a file is prepared; the values when they are read.
    let (disk, _) = prepare();
    let mut bad = good.clone();
    let z0_bytes = vae.tokens() * vae.config.model.latent_channels() * 4;
    bad[48 + z0_bytes..48 + z0_bytes + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&file, &bad).unwrap();
    let err = disk.read(&store, &[0]).unwrap_err().to_string();
    assert!(
        err.contains("shard-00000.latents") && err.contains("clip 0 mu") && err.contains("finite"),
        "{err}"
    );
    let fine = disk.read(&store, &[1, 2]).unwrap();
    assert_eq!(fine.clips.len(), 2);
    assert_eq!(fine.clips[1].caption, store.get(2).unwrap().clip.caption);
}

/// Without `--latents` a run encodes the files into `latents/` of its own folder, and its resume reuses them.
#[test]
fn a_run_keeps_its_latent_files_and_its_resume_reuses_them() {
    let _g = serial();
    let f = fixture();
    let store = sharded_synth_store(&f.dir.join("own"), 1, 2);
    let mut cfg = tiny_rf(LatentCache::Disk);
    cfg.train.checkpoint_every = 1;
    cfg.train.valid_every = 1;
    let opts = |name: &str| RfRunOptions {
        run: run_options(&store, &f.dir, name),
        vae_run: Some(f.vae_run.clone()),
        init: None,
        latents: None,
    };
    let (run, outcome) = train_rf(&cfg, &opts("disk")).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 2, .. }), "{outcome:?}");
    for k in 0..2 {
        assert!(shard_file(&run.path(LATENTS_DIR), k).is_file());
    }
    let log = std::fs::read_to_string(run.path(LOG_FILE)).unwrap();
    assert!(log.contains("0 shard(s) reused, 2 encoded"), "{log}");
    // Resuming the finished run builds its objective again: the files are current.
    // --latents with another cache would be ignored: refused, before a run folder is claimed.
    let mut memory = tiny_rf(LatentCache::Memory);
    memory.train.checkpoint_every = 1;
    let with_dir = RfRunOptions {
        latents: Some(f.dir.join("somewhere")),
        ..opts("memory")
    };
    let err = train_rf(&memory, &with_dir).err().unwrap().to_string();
    assert!(err.contains("--latents") && err.contains("latent_cache"), "{err}");
    assert!(!f.dir.join("runs/memory-1").exists());
    let resumed = resume_rf(run.root(), None, &opts("disk")).unwrap();
    assert!(matches!(resumed, Outcome::Finished { steps: 2, .. }), "{resumed:?}");
    let log = std::fs::read_to_string(run.path(LOG_FILE)).unwrap();
    assert!(log.contains("2 shard(s) reused, 0 encoded"), "{log}");
}
