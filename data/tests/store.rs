//! The dataset store end to end (docs/method.md §2.1–§2.5): import, re-import, split by object, corruption, synth,
//! inspect, burn batches.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use any4d_data::Clip;
use any4d_data::batch::{ClipBatcher, ClipDataset, PadTo, Subset};
use any4d_data::formats;
use any4d_data::fps::farthest_point_sampling;
use any4d_data::inspect::{Inspection, inspect, summarize};
use any4d_data::preprocess::{VertexFilter, normalize};
use any4d_data::store::{self, ImportOptions, Split, Status, Store, read_index};
use any4d_data::synth::SynthConfig;
use burn::data::dataloader::batcher::Batcher;
use burn::data::dataset::Dataset;
use burn::prelude::*;

/// A deterministic wobbly blob of `n` vertices over `frames` frames, with a triangle strip.
fn blob(id: &str, frames: usize, n: usize, seed: u32) -> Clip {
    let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(7);
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        (s as f32 / u32::MAX as f32) * 2.0 - 1.0
    };
    let base: Vec<[f32; 3]> = (0..n).map(|_| [next() * 3.0 + 10.0, next() * 2.0, next()]).collect();
    let vertices = (0..frames)
        .flat_map(|f| {
            base.iter()
                .map(move |p| [p[0] + 0.1 * f as f32, p[1] * (1.0 + 0.05 * f as f32), p[2]])
        })
        .collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    Clip::new(id, vertices, frames, n, faces, format!("caption of {id}"), "test").unwrap()
}

fn opts() -> ImportOptions {
    ImportOptions {
        filter: VertexFilter { min: 16, max: 64 },
        frames: 16,
        stride: 1,
        p: 8,
        ..ImportOptions::default()
    }
}

/// A source folder: three good clips, one 20-frame clip (5 windows), one too small, one garbage, one ignored file.
fn sources(dir: &Path) -> PathBuf {
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("nested")).unwrap();
    formats::write_clip(
        &src.join("objA_offset0_0-15.bin"),
        &blob("objA_offset0_0-15", 16, 20, 1),
    )
    .unwrap();
    formats::write_clip(
        &src.join("objB_offset0_0-15.bin"),
        &blob("objB_offset0_0-15", 16, 32, 2),
    )
    .unwrap();
    formats::write_clip(
        &src.join("nested/objC_offset0_0-15.bin"),
        &blob("objC_offset0_0-15", 16, 64, 3),
    )
    .unwrap();
    formats::write_clip(
        &src.join("objL_offset0_0-19.bin"),
        &blob("objL_offset0_0-19", 20, 24, 4),
    )
    .unwrap();
    formats::write_clip(&src.join("objS_offset0_0-15.bin"), &blob("objS_offset0_0-15", 16, 8, 5)).unwrap();
    std::fs::write(src.join("garbage.bin"), b"this is not a pickle").unwrap();
    std::fs::write(src.join("notes.txt"), b"ignored").unwrap();
    src
}

#[test]
fn import_stores_normalised_windows_and_rejects_bad_files() {
    let tmp = tempfile::tempdir().unwrap();
    let src = sources(tmp.path());
    let out = tmp.path().join("store");
    let report = store::import(std::slice::from_ref(&src), &out, &opts()).unwrap();
    assert_eq!(report.sources, 6, "{report}");
    assert_eq!(report.added, 3 + 5, "{report}");
    let names: Vec<&str> = report
        .rejected
        .iter()
        .map(|r| r.source.rsplit('/').next().unwrap())
        .collect();
    assert_eq!(names, ["garbage.bin", "objS_offset0_0-15.bin"], "{report}");
    assert!(report.rejected[1].reason.contains("vertices"), "{report}");

    let st = Store::open(&out).unwrap();
    assert_eq!((st.len(), st.frames(), st.p()), (8, 16, 8));
    let original = formats::read_clip(&src.join("objB_offset0_0-15.bin")).unwrap();
    let i = (0..st.len())
        .find(|&i| st.get(i).unwrap().clip.id == original.id)
        .unwrap();
    let got = st.get(i).unwrap();
    let (expect, norm) = normalize(&original);
    assert_eq!(
        got.clip.vertices, expect.vertices,
        "stored vertices are normalised by frame 0"
    );
    assert_eq!(got.normalization, norm);
    assert_eq!(got.fps, farthest_point_sampling(expect.frame(0), 8));
    assert_eq!(got.clip.faces, original.faces);
    assert_eq!(got.clip.caption, "caption of objB_offset0_0-15");
    // The frame-0 box of a stored clip is centred with L∞ half-extent 1 (D1)–(D3).
    let f0 = got.clip.frame(0);
    let max = f0.iter().flat_map(|p| p.iter().map(|x| x.abs())).fold(0.0f32, f32::max);
    assert!((max - 1.0).abs() < 1e-5, "{max}");

    let rows = read_index(&out).unwrap();
    assert_eq!(rows.len(), 10);
    assert!(rows[..8].iter().all(|r| r.status == Status::Ok && r.split.is_some()));
    assert!(
        rows[8..]
            .iter()
            .all(|r| r.status == Status::Rejected && !r.reason.is_empty() && r.split.is_none())
    );
    // The windows of the long clip share one object and therefore one split.
    let long: Vec<_> = rows
        .iter()
        .filter(|r| r.source.ends_with("objL_offset0_0-19.bin"))
        .collect();
    assert_eq!(long.len(), 5);
    assert!(long.iter().all(|r| r.object == "objL" && r.split == long[0].split));

    // Training draws one window per whole clip (docs/method.md §2.6): the five windows form one group.
    let all: Vec<usize> = (0..st.len()).collect();
    let mut sizes: Vec<usize> = st.whole_clips(&all).unwrap().iter().map(Vec::len).collect();
    sizes.sort();
    assert_eq!(sizes, [1, 1, 1, 5]);
    let sources = st.sources(&all).unwrap();
    let long_positions: Vec<usize> = (0..st.len())
        .filter(|&i| sources[i].ends_with("objL_offset0_0-19.bin"))
        .collect();
    assert!(st.whole_clips(&all).unwrap().contains(&long_positions));
}

#[test]
fn reimport_is_idempotent_and_unions_other_sources() {
    let tmp = tempfile::tempdir().unwrap();
    let src = sources(tmp.path());
    let out = tmp.path().join("store");
    let first = store::import(&[src.join("objA_offset0_0-15.bin"), src.join("nested")], &out, &opts()).unwrap();
    assert_eq!((first.added, first.kept, first.total), (2, 0, 2));
    let bytes = std::fs::read(out.join("clips.bin")).unwrap();
    let rows = read_index(&out).unwrap();

    let again = store::import(&[src.join("objA_offset0_0-15.bin"), src.join("nested")], &out, &opts()).unwrap();
    assert_eq!((again.added, again.kept, again.total), (2, 0, 2));
    assert_eq!(
        std::fs::read(out.join("clips.bin")).unwrap(),
        bytes,
        "same import twice must give the same file"
    );
    assert_eq!(read_index(&out).unwrap(), rows);

    let more = store::import(
        &[src.join("objB_offset0_0-15.bin"), src.join("objS_offset0_0-15.bin")],
        &out,
        &opts(),
    )
    .unwrap();
    assert_eq!((more.added, more.kept, more.total), (1, 2, 3));
    let ids: Vec<String> = read_index(&out).unwrap().into_iter().map(|r| r.id).collect();
    // Sources are processed in canonical-path order (`nested/` sorts before `objA…`); kept clips come first.
    assert_eq!(
        ids,
        [
            "objC_offset0_0-15",
            "objA_offset0_0-15",
            "objB_offset0_0-15",
            "objS_offset0_0-15.bin"
        ]
    );
    // Re-importing a source replaces its clips instead of duplicating them.
    let b = store::import(&[src.join("objB_offset0_0-15.bin")], &out, &opts()).unwrap();
    assert_eq!((b.added, b.kept, b.total), (1, 2, 3));
    assert_eq!(read_index(&out).unwrap().len(), 4);
}

#[test]
fn import_refuses_foreign_folders_and_mismatched_stores() {
    let tmp = tempfile::tempdir().unwrap();
    let src = sources(tmp.path());
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("thesis.tex"), b"precious").unwrap();
    let e = store::import(&[src.join("objA_offset0_0-15.bin")], &foreign, &opts()).unwrap_err();
    assert!(e.reason.contains("not empty") && e.reason.contains("thesis.tex"), "{e}");
    assert_eq!(std::fs::read(foreign.join("thesis.tex")).unwrap(), b"precious");

    let out = tmp.path().join("store");
    store::import(&[src.join("objA_offset0_0-15.bin")], &out, &opts()).unwrap();
    let e = store::import(
        &[src.join("objB_offset0_0-15.bin")],
        &out,
        &ImportOptions { p: 4, ..opts() },
    )
    .unwrap_err();
    assert!(e.reason.contains("P = 8") && e.reason.contains("P = 4"), "{e}");
    // A missing source is a rejection, not an abort.
    let r = store::import(&[tmp.path().join("nope.bin")], &out, &opts()).unwrap();
    assert_eq!(r.rejected.len(), 1);
    assert!(r.rejected[0].source.ends_with("nope.bin"), "{r}");
}

#[test]
fn split_groups_clips_by_object() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir(&src).unwrap();
    for obj in 0..40 {
        for k in 0..3 {
            let id = format!("object{obj}_offset{k}_0-15");
            formats::write_clip(&src.join(format!("{id}.bin")), &blob(&id, 16, 16, obj * 10 + k)).unwrap();
        }
    }
    let out = tmp.path().join("store");
    let report = store::import(&[src], &out, &opts()).unwrap();
    assert_eq!(report.total, 120);
    assert!(report.val > 0 && report.train > report.val, "{report}");
    let rows = read_index(&out).unwrap();
    let st = Store::open(&out).unwrap();
    for obj in 0..40 {
        let uid = format!("object{obj}");
        let sides: Vec<Split> = rows
            .iter()
            .filter(|r| r.object == uid)
            .map(|r| r.split.unwrap())
            .collect();
        assert_eq!(sides.len(), 3);
        assert!(sides.iter().all(|&s| s == sides[0]), "{uid} is on both sides");
        assert_eq!(sides[0], Split::of_object(&uid, store::SPLIT_SEED));
    }
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(
            st.split(i).unwrap(),
            row.split.unwrap(),
            "clips.bin and index disagree at {i}"
        );
    }
}

#[test]
fn corrupt_or_truncated_store_gives_errors_not_panics() {
    let tmp = tempfile::tempdir().unwrap();
    let src = sources(tmp.path());
    let out = tmp.path().join("store");
    store::import(
        &[src.join("objA_offset0_0-15.bin"), src.join("objB_offset0_0-15.bin")],
        &out,
        &opts(),
    )
    .unwrap();
    let path = out.join("clips.bin");
    let good = std::fs::read(&path).unwrap();

    std::fs::write(&path, &good[..good.len() - 5]).unwrap();
    let e = Store::open(&out).unwrap_err();
    assert!(e.path.ends_with("clips.bin") && e.field.contains("byte"), "{e}");

    let mut bad = good.clone();
    bad[..8].copy_from_slice(b"NOTASTOR");
    std::fs::write(&path, &bad).unwrap();
    let e = Store::open(&out).unwrap_err();
    assert!(
        e.field.contains("magic") && e.reason.contains("not an any4d store"),
        "{e}"
    );

    // The first record's frame count (after three length-prefixed strings) made huge.
    let mut bad = good.clone();
    let mut at = 24;
    for _ in 0..3 {
        at += 4 + u32::from_le_bytes(bad[at..at + 4].try_into().unwrap()) as usize;
    }
    bad[at + 4..at + 8].copy_from_slice(&u32::MAX.to_le_bytes()); // N
    std::fs::write(&path, &bad).unwrap();
    let st = Store::open(&out).unwrap();
    let e = st.get(0).unwrap_err();
    assert!(e.field.contains("clip 0 vertices at byte"), "{e}");

    // The first record's source length made huge: `sources` names the field instead of reading past the record.
    let mut bad = good.clone();
    let mut at = 24;
    for _ in 0..2 {
        at += 4 + u32::from_le_bytes(bad[at..at + 4].try_into().unwrap()) as usize;
    }
    bad[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(&path, &bad).unwrap();
    let e = Store::open(&out).unwrap().sources(&[0]).unwrap_err();
    assert!(
        e.field.contains("clip 0 source at byte") && e.reason.contains("past the record"),
        "{e}"
    );

    // Every truncation and every single-byte flip is an error or a clean read, never a panic.
    let every: Vec<usize> = (0..2).collect();
    for cut in (0..good.len()).step_by(7) {
        std::fs::write(&path, &good[..cut]).unwrap();
        if let Ok(st) = Store::open(&out) {
            for i in 0..st.len() {
                let _ = st.get(i);
            }
            let _ = st.whole_clips(&every[..st.len().min(2)]);
        }
    }
    for pos in (0..good.len()).step_by(11) {
        let mut bad = good.clone();
        bad[pos] ^= 0xa5;
        std::fs::write(&path, &bad).unwrap();
        if let Ok(st) = Store::open(&out) {
            for i in 0..st.len() {
                let _ = st.get(i);
            }
            let _ = st.whole_clips(&every[..st.len().min(2)]);
        }
    }
}

#[test]
fn synth_store_inspect_and_batches() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("synth");
    let cfg = SynthConfig {
        clips: 6,
        seed: 3,
        ..SynthConfig::default()
    };
    let report = store::write_synth_with(&cfg, &out, 16, None).unwrap();
    assert_eq!((report.total, report.rejected.len()), (6, 0), "{report}");
    let again = store::write_synth_with(&cfg, &out, 16, None).unwrap();
    assert_eq!(again.total, 6, "same seed replaces, never duplicates");

    let Inspection::Store(s) = inspect(&out).unwrap() else {
        panic!("a store folder is a store")
    };
    assert_eq!(s, summarize(&out).unwrap());
    assert_eq!((s.clips, s.ok, s.rejected, s.train + s.val), (6, 6, 0, 6));
    assert_eq!(s.synthetic_families.values().sum::<usize>(), 6, "{s:?}");

    let st = Arc::new(Store::open(&out).unwrap());
    let ds = ClipDataset::new(st.clone(), Subset::All);
    assert_eq!(ds.len(), 6);
    let train = ClipDataset::new(st.clone(), Subset::Only(Split::Train));
    assert_eq!(train.len(), s.train);
    let items: Vec<_> = (0..3).map(|i| ds.get(i).unwrap()).collect();
    let n_max = items.iter().map(|c| c.clip.n_vertices).max().unwrap();
    let device = Device::flex();
    let batch = ClipBatcher::new(PadTo::BatchMax).batch(items.clone(), &device);
    assert_eq!(batch.vertices.dims(), [3, cfg.frames, n_max, 3]);
    assert_eq!(batch.vmask.dims(), [3, n_max]);
    assert_eq!(batch.fps.dims(), [3, 16]);
    let mask: Vec<bool> = batch.vmask.to_data().try_to_vec::<bool>().unwrap();
    for (b, item) in items.iter().enumerate() {
        let n = item.clip.n_vertices;
        assert!(mask[b * n_max..b * n_max + n].iter().all(|&m| m));
        assert!(mask[b * n_max + n..(b + 1) * n_max].iter().all(|&m| !m));
        assert_eq!(batch.n_real[b], n);
        assert!(batch.edges[b].iter().all(|e| e[0] < e[1] && (e[1] as usize) < n));
    }
    let v: Vec<f32> = batch.vertices.to_data().try_to_vec::<f32>().unwrap();
    let n0 = items[0].clip.n_vertices;
    assert_eq!(v[..3], items[0].clip.vertices[0]);
    if n0 < n_max {
        assert_eq!(
            v[n0 * 3..n_max * 3].iter().filter(|&&x| x != 0.0).count(),
            0,
            "padding is zero"
        );
    }
    let fps: Vec<i64> = batch.fps.to_data().convert::<i64>().try_to_vec::<i64>().unwrap();
    assert_eq!(fps[..16].iter().map(|&i| i as u32).collect::<Vec<_>>(), items[0].fps);
    let e = ClipBatcher::new(PadTo::Fixed(n_max - 1))
        .try_batch(&items, &device)
        .unwrap_err();
    assert!(e.reason.contains("exceed"), "{e}");
}

/// Short takes (docs/method.md §2.6): a take shorter than the window is rejected unless `loop_short` is on and the
/// take is a cycle, which is then played round to the window's length.
#[test]
fn short_takes_loop_only_when_asked_and_only_when_they_cycle() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir_all(&src).unwrap();
    // A 24-vertex ring turning once in 6 frames (frame 6 would equal frame 0), and a blob drifting away.
    let n = 24;
    let ring: Vec<[f32; 3]> = (0..6)
        .flat_map(|f| {
            (0..n).map(move |v| {
                let a = std::f32::consts::TAU * (v as f32 / n as f32 + f as f32 / 6.0);
                [a.cos(), a.sin(), (v % 3) as f32 * 0.1]
            })
        })
        .collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    let cycle = Clip::new("spin_offset0_0-5", ring, 6, n, faces, "a spinning ring", "test").unwrap();
    formats::write_clip(&src.join("spin_offset0_0-5.bin"), &cycle).unwrap();
    formats::write_clip(&src.join("drift_offset0_0-5.bin"), &blob("drift_offset0_0-5", 6, 20, 9)).unwrap();

    let off = store::import(std::slice::from_ref(&src), &tmp.path().join("off"), &opts()).unwrap();
    assert_eq!((off.added, off.rejected.len()), (0, 2), "{off}");
    assert!(off.rejected.iter().all(|r| r.reason.contains("--loop-short")), "{off}");

    let on = ImportOptions {
        loop_short: true,
        ..opts()
    };
    let out = tmp.path().join("on");
    let report = store::import(std::slice::from_ref(&src), &out, &on).unwrap();
    assert_eq!(report.added, 1, "{report}");
    assert_eq!(report.rejected.len(), 1, "{report}");
    assert!(report.rejected[0].source.ends_with("drift_offset0_0-5.bin"), "{report}");
    assert!(report.rejected[0].reason.contains("does not loop"), "{report}");
    let st = Store::open(&out).unwrap();
    let got = st.get(0).unwrap();
    assert_eq!((got.clip.id.as_str(), got.clip.frames), ("spin_offset0_0-5_loop", 16));
    // Played round: frame f of the window is frame f mod 6 of the take, normalised as one window.
    let (expect, _) = normalize(&cycle);
    for f in 0..16 {
        assert_eq!(got.clip.frame(f), expect.frame(f % 6), "frame {f}");
    }
    assert_eq!(read_index(&out).unwrap()[0].object, "spin");
}

/// A store read with numpy alone (`scripts/read_any4d.py store`, the reader docs/pytorch.md shows): its T, P, clip
/// count and the first clip's id, caption and array shapes are the store's.
#[test]
fn numpy_reads_a_store() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("store");
    let cfg = SynthConfig {
        clips: 3,
        seed: 5,
        frames: 4,
        ..SynthConfig::default()
    };
    store::write_synth_with(&cfg, &out, 16, None).unwrap();
    let s = Store::open(&out).unwrap();
    let first = s.get(0).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/read_any4d.py");
    let run = std::process::Command::new("python3")
        .arg(&script)
        .arg("store")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{stdout}{}", String::from_utf8_lossy(&run.stderr));
    assert!(stdout.contains(&format!("T 4 P 16 clips {}", s.len())), "{stdout}");
    let c = &first.clip;
    let want = format!(
        "first: {:?} {:?} vertices (4, {}, 3) faces ({}, 3) fps (16,)",
        c.id,
        c.caption,
        c.n_vertices,
        c.faces.len()
    );
    assert!(stdout.contains(&want.replace('"', "'")), "{stdout}\nwant {want}");
}
