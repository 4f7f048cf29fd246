//! Sharded stores end to end: shards written by separate imports, merged by a manifest, read as one store, and
//! every way a manifest or shard can be wrong (a clear error naming the shard, nothing half-written).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use any4d_data::Clip;
use any4d_data::formats;
use any4d_data::inspect::summarize;
use any4d_data::preprocess::VertexFilter;
use any4d_data::store::{
    self, ImportOptions, MANIFEST_FILE, ShardSpec, Status, Store, check_index, read_index, verify_store,
    write_synth_shard, write_synth_windows,
};
use any4d_data::synth::SynthConfig;

fn synth_cfg() -> SynthConfig {
    SynthConfig {
        clips: 12,
        seed: 5,
        frames: 16,
        min_vertices: 256,
        max_vertices: 512,
        ..SynthConfig::default()
    }
}

const P: usize = 8;

/// `n` shards of the synth config under `store/shard-K`, merged; returns the shard folders.
fn sharded(store: &Path, n: usize) -> Vec<PathBuf> {
    let dirs: Vec<PathBuf> = (0..n).map(|k| store.join(format!("shard-{k}"))).collect();
    for (k, dir) in dirs.iter().enumerate() {
        let spec = ShardSpec { index: k, count: n };
        write_synth_shard(&synth_cfg(), dir, P, (16, 1), Some(spec), None).unwrap();
    }
    store::merge(store, &dirs).unwrap();
    dirs
}

/// id → (raw record, split) of every clip.
fn by_id(s: &Store) -> BTreeMap<String, (Vec<u8>, store::Split)> {
    (0..s.len())
        .map(|i| (s.get(i).unwrap().clip.id, (s.raw(i).unwrap(), s.split(i).unwrap())))
        .collect()
}

#[test]
fn shards_merged_hold_exactly_the_one_file_store() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    write_synth_windows(&synth_cfg(), &whole, P, 16, 1, None).unwrap();
    let root = tmp.path().join("sharded");
    let dirs = sharded(&root, 3);
    let one = Store::open(&whole).unwrap();
    let many = Store::open(&root).unwrap();
    assert_eq!(many.shard_count(), 3);
    assert_eq!(one.shard_count(), 1);
    assert_eq!(
        (many.len(), many.frames(), many.p()),
        (one.len(), one.frames(), one.p())
    );
    // The same records, on the same side of the split: sharding changes where a clip lives, nothing else.
    assert_eq!(by_id(&many), by_id(&one));
    // Clips are numbered shard after shard.
    let mut start = 0;
    for (k, dir) in dirs.iter().enumerate() {
        let shard = Store::open(dir).unwrap();
        assert_eq!(many.shard_range(k), start..start + shard.len());
        for j in 0..shard.len() {
            assert_eq!(many.raw(start + j).unwrap(), shard.raw(j).unwrap());
            assert_eq!(many.shard_of(start + j).unwrap(), k);
        }
        start += shard.len();
    }
    assert!(many.get(many.len()).is_err());
    // The index reads whole: stored rows in clip order, then the rejected ones; it pairs with the clips.
    let rows = read_index(&root).unwrap();
    check_index(&many, &rows).unwrap();
    let ids: Vec<String> = (0..many.len()).map(|i| many.get(i).unwrap().clip.id).collect();
    let listed: Vec<String> = rows
        .iter()
        .filter(|r| r.status == Status::Ok)
        .map(|r| r.id.clone())
        .collect();
    assert_eq!(ids, listed);
    // Verify and inspect see the whole store and its shards.
    let report = verify_store(&root).unwrap();
    assert!(report.is_ok(), "{report}");
    assert_eq!((report.clips, report.shards), (many.len(), Some(3)));
    let summary = summarize(&root).unwrap();
    assert_eq!(summary.ok, many.len());
    let shards = summary.shards.unwrap();
    assert_eq!(shards.iter().map(|s| s.clips).sum::<usize>(), many.len());
    assert!(
        shards.iter().all(|s| s.path.starts_with("shard-")),
        "relative paths: {shards:?}"
    );
    // Every shard still verifies alone.
    for dir in &dirs {
        assert!(verify_store(dir).unwrap().is_ok());
    }
}

#[test]
fn a_moved_store_still_opens_and_shards_outside_are_absolute() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("a");
    sharded(&root, 2);
    let moved = tmp.path().join("b");
    std::fs::rename(&root, &moved).unwrap();
    assert!(Store::open(&moved).is_ok());
    // Shards outside the store folder are recorded by absolute path.
    let outside = tmp.path().join("outside");
    write_synth_shard(&synth_cfg(), &outside, P, (16, 1), None, None).unwrap();
    let m = store::merge(&tmp.path().join("c"), std::slice::from_ref(&outside)).unwrap();
    assert!(Path::new(&m.shards[0].path).is_absolute());
    assert_eq!(Store::open(&tmp.path().join("c")).unwrap().len(), 12);
}

/// A tree of 9 small clip files (one of them unreadable) under `dir/corpus`.
fn corpus(dir: &Path) -> PathBuf {
    let src = dir.join("corpus");
    for i in 0..8 {
        let sub = src.join(format!("set{}", i % 3));
        std::fs::create_dir_all(&sub).unwrap();
        let id = format!("obj{i}_offset0_0-15");
        let n = 20 + i;
        let vertices = (0..16)
            .flat_map(|f| (0..n).map(move |v| [v as f32 * 0.1, (v % 5) as f32 + 0.01 * f as f32, (v % 3) as f32]))
            .collect();
        let faces = (0..n as u32 - 2).map(|v| [v, v + 1, v + 2]).collect();
        let clip = Clip::new(&id, vertices, 16, n, faces, "a clip", "test").unwrap();
        formats::write_clip(&sub.join(format!("{id}.bin")), &clip).unwrap();
    }
    std::fs::write(src.join("set0/broken.bin"), b"not a clip").unwrap();
    src
}

fn import_opts(shard: Option<ShardSpec>) -> ImportOptions {
    ImportOptions {
        filter: VertexFilter { min: 16, max: 64 },
        p: P,
        shard,
        ..ImportOptions::default()
    }
}

/// The file names (below the corpus) of the sources a store holds, stored or rejected.
fn names(dir: &Path) -> BTreeSet<String> {
    read_index(dir)
        .unwrap()
        .into_iter()
        .map(|r| Path::new(&r.source).file_name().unwrap().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn import_shards_partition_the_files_by_their_path_below_the_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let src = corpus(tmp.path());
    let whole = tmp.path().join("whole");
    store::import(std::slice::from_ref(&src), &whole, &import_opts(None)).unwrap();
    let n = 3;
    let mut union = BTreeSet::new();
    let mut dirs = Vec::new();
    for k in 0..n {
        let dir = tmp.path().join(format!("s/shard-{k}"));
        let report = store::import(
            std::slice::from_ref(&src),
            &dir,
            &import_opts(Some(ShardSpec { index: k, count: n })),
        )
        .unwrap();
        let got = names(&dir);
        assert_eq!(report.sources, got.len());
        assert!(union.is_disjoint(&got), "a file in two shards: {got:?}");
        union.extend(got);
        dirs.push(dir);
    }
    assert_eq!(union, names(&whole));
    store::merge(&tmp.path().join("s"), &dirs).unwrap();
    assert_eq!(
        Store::open(&tmp.path().join("s")).unwrap().len(),
        Store::open(&whole).unwrap().len()
    );
    // The same tree elsewhere gives the same shard its same files: the key is the path below the folder given.
    let copy = tmp.path().join("elsewhere/deeper/corpus");
    std::fs::create_dir_all(copy.parent().unwrap()).unwrap();
    std::fs::rename(&src, &copy).unwrap();
    let again = tmp.path().join("again");
    store::import(&[copy], &again, &import_opts(Some(ShardSpec { index: 1, count: n }))).unwrap();
    assert_eq!(names(&again), names(&dirs[1]));
}

#[test]
fn reimporting_a_shard_rewrites_only_that_shard_and_the_manifest_notices() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("s");
    let dirs = sharded(&root, 2);
    let before0 = std::fs::read(dirs[0].join("clips.bin")).unwrap();
    // Another generator seed joins shard 1 only.
    let more = SynthConfig {
        seed: 77,
        clips: 8,
        ..synth_cfg()
    };
    let report = write_synth_shard(
        &more,
        &dirs[1],
        P,
        (16, 1),
        Some(ShardSpec { index: 1, count: 2 }),
        None,
    )
    .unwrap();
    assert!(report.added > 0, "seed 77 puts clips in shard 1");
    assert_eq!(std::fs::read(dirs[0].join("clips.bin")).unwrap(), before0);
    // Until merged again, the manifest no longer describes shard 1.
    let e = Store::open(&root).unwrap_err().to_string();
    assert!(e.contains("shard-1") && e.contains("data merge"), "{e}");
    store::merge(&root, &dirs).unwrap();
    assert!(Store::open(&root).unwrap().len() > 12);
    // Importing into the sharded store's own folder is refused: it would write beside the shards.
    let e = write_synth_windows(&more, &root, P, 16, 1, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("sharded store") && e.contains("--shard"), "{e}");
}

fn manifest_text(root: &Path) -> String {
    std::fs::read_to_string(root.join(MANIFEST_FILE)).unwrap()
}

#[test]
fn broken_manifests_and_shards_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("s");
    let dirs = sharded(&root, 2);
    let good = manifest_text(&root);
    let open_err = |text: &str| {
        std::fs::write(root.join(MANIFEST_FILE), text).unwrap();
        let e = Store::open(&root).unwrap_err().to_string();
        std::fs::write(root.join(MANIFEST_FILE), &good).unwrap();
        e
    };
    for (text, want) in [
        ("{", "line 1"),
        ("[]", "manifest"),
        ("", "line 1"),
        (&good.replace("\"version\": 1", "\"version\": 9"), "version"),
        (&good.replace("any4d-sharded-store", "other"), "format"),
        (&good.replace("\"seed\": 666", "\"seed\": 1"), "split"),
        (&good.replace("\"frames\": 16", "\"frames\": 17"), "T = 16"),
        (&good.replace("\"clips\"", "\"cilps\""), "unknown field"),
        (&good.replace("shard-1", "shard-0"), "also shard 0"),
        (&good.replace("shard-1", "shard-9"), "missing"),
        (&good.replace("shard-1", "../../../../../../etc"), "missing"),
    ] {
        let e = open_err(text);
        assert!(e.contains(want) && e.contains(MANIFEST_FILE), "{want}: {e}");
    }
    let empty = serde_json::to_string(&{
        let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
        v["shards"] = serde_json::json!([]);
        v
    })
    .unwrap();
    assert!(open_err(&empty).contains("1 to"));
    // A shard claiming a gigantic clip count is refused before anything is allocated for it.
    let huge = good.replacen(
        &format!("\"clips\": {}", Store::open(&dirs[0]).unwrap().len()),
        "\"clips\": 18446744073709551615",
        1,
    );
    assert!(open_err(&huge).contains("clips"));
    assert!(Store::open(&root).is_ok(), "restored");

    // A truncated shard: named, with the sizes.
    let clips1 = dirs[1].join("clips.bin");
    let bytes = std::fs::read(&clips1).unwrap();
    std::fs::write(&clips1, &bytes[..bytes.len() - 10]).unwrap();
    let e = Store::open(&root).unwrap_err().to_string();
    assert!(e.contains("shard-1") && e.contains("truncated"), "{e}");
    assert!(verify_store(&root).is_err());
    // A shard of the right size whose bytes changed: open cannot tell, verify names it by its checksum.
    let mut flipped = bytes.clone();
    flipped[40] ^= 0xff;
    std::fs::write(&clips1, &flipped).unwrap();
    let e = verify_store(&root).unwrap_err().to_string();
    assert!(e.contains("shard-1") && e.contains("checksum"), "{e}");
    std::fs::write(&clips1, &bytes).unwrap();
    assert!(verify_store(&root).unwrap().is_ok());
    // A missing shard.
    std::fs::rename(&dirs[0], tmp.path().join("gone")).unwrap();
    let e = Store::open(&root).unwrap_err().to_string();
    assert!(e.contains("shard-0") && e.contains("missing"), "{e}");
}

#[test]
fn merges_that_cannot_be_one_store_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    let c = tmp.path().join("c");
    write_synth_shard(
        &synth_cfg(),
        &a,
        P,
        (16, 1),
        Some(ShardSpec { index: 0, count: 2 }),
        None,
    )
    .unwrap();
    // The whole config again: every source of `a` is in `b` too.
    write_synth_shard(&synth_cfg(), &b, P, (16, 1), None, None).unwrap();
    // Another P.
    write_synth_shard(
        &synth_cfg(),
        &c,
        P + 1,
        (16, 1),
        Some(ShardSpec { index: 1, count: 2 }),
        None,
    )
    .unwrap();
    let out = tmp.path().join("out");
    for (shards, want) in [
        (vec![a.clone(), b.clone()], "two shards claim"),
        (vec![a.clone(), c.clone()], "must agree"),
        (vec![a.clone(), a.clone()], "named twice"),
        (vec![a.clone(), tmp.path().join("nowhere")], "nowhere"),
        (vec![], "no shard"),
    ] {
        let e = store::merge(&out, &shards).unwrap_err().to_string();
        assert!(e.contains(want), "{want}: {e}");
        assert!(!out.exists(), "{want}: the store folder was made");
    }
    // A one-file store cannot become a sharded one in place, nor a sharded store a shard.
    let e = store::merge(&a, std::slice::from_ref(&b)).unwrap_err().to_string();
    assert!(e.contains("one-file store"), "{e}");
    store::merge(&out, std::slice::from_ref(&a)).unwrap();
    let e = store::merge(&tmp.path().join("out2"), std::slice::from_ref(&out))
        .unwrap_err()
        .to_string();
    assert!(e.contains("itself a sharded store"), "{e}");
    // A folder with both a manifest and clips.bin is ambiguous.
    std::fs::copy(a.join("clips.bin"), out.join("clips.bin")).unwrap();
    let e = Store::open(&out).unwrap_err().to_string();
    assert!(e.contains("both"), "{e}");
}

/// A shard larger than the bound is refused before anything is written, naming it and a shard count that fits; the
/// size flag's parser takes units and refuses zero, signs, fractions, unknown units and overflow.
#[test]
fn shards_over_the_size_bound_are_refused_with_a_count_that_fits() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let dirs: Vec<PathBuf> = (0..2).map(|k| store.join(format!("shard-{k}"))).collect();
    for (k, dir) in dirs.iter().enumerate() {
        let spec = ShardSpec { index: k, count: 2 };
        write_synth_shard(&synth_cfg(), dir, P, (16, 1), Some(spec), None).unwrap();
    }
    let sizes: Vec<u64> = dirs
        .iter()
        .map(|d| std::fs::metadata(d.join("clips.bin")).unwrap().len())
        .collect();
    let bound = sizes.iter().min().unwrap() - 1;
    let e = store::merge_bounded(&store, &dirs, bound).unwrap_err().to_string();
    let n = ((sizes.iter().sum::<u64>() as f64) * 1.25 / bound as f64).ceil() as u64;
    assert!(
        e.contains("shard-0") && e.contains("shard-1") && e.contains(&format!("--shard K/{n}")),
        "{e}"
    );
    assert!(!store.join(MANIFEST_FILE).exists());
    // At the larger shard's size exactly, the merge goes through.
    store::merge_bounded(&store, &dirs, *sizes.iter().max().unwrap()).unwrap();
    assert_eq!(store::DEFAULT_MAX_SHARD_BYTES, 1 << 30);

    for (text, want) in [
        ("1GiB", 1u64 << 30),
        ("500M", 500_000_000),
        ("2kb", 2_000),
        ("7", 7),
        (" 3 TiB ", 3 << 40),
    ] {
        assert_eq!(store::parse_bytes(text), Ok(want), "{text}");
    }
    for (bad, why) in [
        ("0", "positive"),
        ("0G", "positive"),
        ("-1G", "not a size"),
        ("1.5G", "unknown unit"),
        ("12XB", "unknown unit"),
        ("GiB", "not a size"),
        ("", "not a size"),
        ("99999999999999999999", "2^64"),
        ("20000000TiB", "2^64"),
    ] {
        let e = store::parse_bytes(bad).unwrap_err();
        assert!(e.contains(why), "{bad:?}: {e}");
    }
}
