//! Hostile input at the store level: imports that survive bad files, stores checked against their index and
//! their checksums, and size options refused before anything is allocated.

use std::path::{Path, PathBuf};

use any4d_data::Clip;
use any4d_data::formats;
use any4d_data::inspect::summarize;
use any4d_data::preprocess::VertexFilter;
use any4d_data::store::{
    self, CHECKSUM_COLUMN, ImportOptions, Status, Store, Weld, read_index, verify_store, write_synth_windows,
};
use any4d_data::synth::SynthConfig;
use polars::prelude::*;

/// A moving blob of `n` vertices: `scale` times a unit-sized shape, shifted by `shift` along x.
fn blob(id: &str, n: usize, scale: f32, shift: f32) -> Clip {
    let frames = 16;
    let vertices = (0..frames)
        .flat_map(|f| {
            (0..n).map(move |k| {
                let a = k as f32 * 0.7;
                [
                    a.sin() * scale + shift,
                    a.cos() * scale,
                    (0.1 * f as f32 + 0.01 * k as f32) * scale,
                ]
            })
        })
        .collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    Clip::new(id, vertices, frames, n, faces, format!("caption of {id}"), "test").unwrap()
}

fn opts() -> ImportOptions {
    ImportOptions {
        filter: VertexFilter { min: 16, max: 64 },
        p: 8,
        ..ImportOptions::default()
    }
}

fn hostile(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/hostile")
        .join(name)
}

/// Two good clips, a pickle bomb, a glTF that used to panic, and clips near ±3.4e38 (finite, but their
/// normalisation overflows).
fn sources(dir: &Path) -> PathBuf {
    let src = dir.join("src");
    std::fs::create_dir_all(&src).unwrap();
    formats::write_clip(&src.join("a.bin"), &blob("a", 20, 1.0, 0.0)).unwrap();
    formats::write_clip(&src.join("b.bin"), &blob("b", 24, 2.0, 0.0)).unwrap();
    // Frame 0 near 3e38: the centre (hi + lo) / 2 overflows.
    formats::write_clip(&src.join("huge.bin"), &blob("huge", 20, 1.0e36, 3.0e38)).unwrap();
    // A tiny frame 0, later frames at ±3e38: dividing by the frame-0 scale overflows.
    let mut far = blob("far", 20, 1.0e-3, 0.0);
    far.vertices
        .iter_mut()
        .skip(20)
        .for_each(|p| p[0] = 3.0e38 * if p[1] > 0.0 { 1.0 } else { -1.0 });
    formats::write_clip(&src.join("far.bin"), &far).unwrap();
    std::fs::copy(hostile("memo_bomb.bin"), src.join("bomb.bin")).unwrap();
    std::fs::copy(hostile("target_node_99.gltf"), src.join("panicked.gltf")).unwrap();
    src
}

#[test]
fn one_bad_file_never_stops_an_import() {
    let tmp = tempfile::tempdir().unwrap();
    let src = sources(tmp.path());
    let out = tmp.path().join("store");
    let report = store::import(&[src], &out, &opts()).unwrap();
    assert_eq!((report.sources, report.added), (6, 2), "{report}");
    let reasons: Vec<(&str, &str)> = report
        .rejected
        .iter()
        .map(|r| (r.source.rsplit('/').next().unwrap(), r.reason.as_str()))
        .collect();
    let reason = |name: &str| reasons.iter().find(|(n, _)| *n == name).unwrap().1;
    assert!(reason("bomb.bin").contains("pickle bomb"), "{report}");
    assert!(reason("panicked.gltf").contains("node 99 does not exist"), "{report}");
    assert!(reason("huge.bin").contains("non-finite"), "{report}");
    assert!(reason("far.bin").contains("non-finite"), "{report}");
    // What was stored reads back, and no temporary file is left.
    let st = Store::open(&out).unwrap();
    for i in 0..st.len() {
        st.get(i).unwrap();
    }
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
    assert!(verify_store(&out).unwrap().is_ok());
}

/// A store of the two good clips.
fn small_store(tmp: &Path) -> PathBuf {
    let src = sources(tmp);
    let out = tmp.join("store");
    store::import(&[src.join("a.bin"), src.join("b.bin")], &out, &opts()).unwrap();
    out
}

#[test]
fn inspect_checks_clips_bin_against_the_index() {
    let tmp = tempfile::tempdir().unwrap();
    let out = small_store(tmp.path());
    let s = summarize(&out).unwrap();
    assert_eq!((s.ok, s.checksums), (2, 2));
    let clips = out.join("clips.bin");
    let good = std::fs::read(&clips).unwrap();
    // An empty clips.bin used to be summarised from the index alone.
    std::fs::write(&clips, b"").unwrap();
    let e = summarize(&out).unwrap_err();
    assert!(
        e.path.ends_with("clips.bin") && e.reason.contains("shorter than header"),
        "{e}"
    );
    // A clips.bin with one clip fewer than the index lists.
    store::import(&[tmp.path().join("src/a.bin")], &tmp.path().join("one"), &opts()).unwrap();
    std::fs::copy(tmp.path().join("one/clips.bin"), &clips).unwrap();
    let e = summarize(&out).unwrap_err();
    assert!(
        e.field == "clip count" && e.reason.contains("holds 1 clips, index.parquet lists 2"),
        "{e}"
    );
    // Same count, but the index's sizes do not match the records.
    std::fs::write(&clips, &good).unwrap();
    let mut rows = read_index(&out).unwrap();
    rows[0].vertices = rows[0].vertices.map(|n| n + 1);
    store::write_index(&out, &rows).unwrap();
    let e = summarize(&out).unwrap_err();
    assert!(e.field.starts_with("clip 0") && e.reason.contains("implies"), "{e}");
}

#[test]
fn verify_finds_bit_flips_by_checksum() {
    let tmp = tempfile::tempdir().unwrap();
    let out = small_store(tmp.path());
    let report = verify_store(&out).unwrap();
    assert_eq!(
        (report.clips, report.with_checksum, report.problems.len()),
        (2, 2, 0),
        "{report}"
    );
    // Flip a low mantissa bit of a coordinate of clip 1: it still decodes, and inspect (sizes) still passes.
    let clips = out.join("clips.bin");
    let mut bytes = std::fs::read(&clips).unwrap();
    let entry = store::read_catalog(&clips).unwrap().entries[1];
    let faces = Store::open(&out).unwrap().get(1).unwrap().clip.faces.len();
    // Records end with vertices | faces (12 B each) | fps (P = 8 × 4 B) | normalisation (16 B): this is the low
    // byte of a coordinate 100 bytes before the end of the vertices.
    let vertices_end = entry.offset + entry.len - 16 - 8 * 4 - 12 * faces as u64;
    bytes[(vertices_end - 100) as usize] ^= 1;
    std::fs::write(&clips, &bytes).unwrap();
    assert!(Store::open(&out).unwrap().get(1).is_ok());
    assert!(summarize(&out).is_ok());
    let report = verify_store(&out).unwrap();
    assert_eq!(report.problems.len(), 1, "{report}");
    assert_eq!(report.problems[0].clip, 1);
    assert!(report.problems[0].reason.contains("checksum"), "{report}");
    // Re-importing on top of a damaged store refuses to copy the damaged clip.
    let e = store::import(&[tmp.path().join("src/a.bin")], &out, &opts()).unwrap_err();
    assert!(e.reason.contains("fails its checksum"), "{e}");
    assert!(
        !out.join("clips.bin.tmp").exists(),
        "the failed import left its temporary file"
    );
}

#[test]
fn stores_without_checksums_still_read_and_gain_them_on_reimport() {
    let tmp = tempfile::tempdir().unwrap();
    let out = small_store(tmp.path());
    // Rewrite the index as an older any4d wrote it: without the checksum column.
    let path = out.join("index.parquet");
    let mut df = ParquetReader::new(std::fs::File::open(&path).unwrap())
        .finish()
        .unwrap();
    df.drop_in_place(CHECKSUM_COLUMN).unwrap();
    ParquetWriter::new(std::fs::File::create(&path).unwrap())
        .finish(&mut df)
        .unwrap();
    assert!(read_index(&out).unwrap().iter().all(|r| r.checksum.is_none()));
    assert_eq!(summarize(&out).unwrap().checksums, 0);
    let report = verify_store(&out).unwrap();
    assert!(report.is_ok() && report.with_checksum == 0, "{report}");
    assert!(report.to_string().contains("re-import"), "{report}");
    // Importing another file keeps the old clips and gives them checksums.
    store::import(&[tmp.path().join("src/huge.bin")], &out, &opts()).unwrap();
    let rows = read_index(&out).unwrap();
    let ok: Vec<_> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    assert!(ok.len() == 2 && ok.iter().all(|r| r.checksum.is_some()));
    assert_eq!(verify_store(&out).unwrap().with_checksum, 2);
}

#[test]
fn failed_import_leaves_no_temporary_file() {
    let tmp = tempfile::tempdir().unwrap();
    let out = small_store(tmp.path());
    // An index whose first id differs from clips.bin (same length, so the sizes still match).
    let mut rows = read_index(&out).unwrap();
    rows[0].id = "z".repeat(rows[0].id.len());
    store::write_index(&out, &rows).unwrap();
    let e = store::import(&[tmp.path().join("src/huge.bin")], &out, &opts()).unwrap_err();
    assert!(e.reason.contains("inconsistent"), "{e}");
    assert!(!out.join("clips.bin.tmp").exists());
    assert!(!out.join("index.parquet.tmp").exists());
}

#[test]
fn weld_refuses_infinite_eps_and_degenerate_results() {
    for eps in [f32::INFINITY, f32::NAN, -1.0] {
        let o = ImportOptions {
            weld: Weld::Eps(eps),
            ..opts()
        };
        assert_eq!(o.validate().unwrap_err().field, "weld", "{eps}");
        assert!(Weld::Eps(eps).apply(blob("a", 20, 1.0, 0.0)).is_err(), "{eps}");
    }
    // Every vertex coincides in every frame: welding leaves one vertex, which is not a clip.
    let frames = 16;
    let v = vec![[0.5, 0.5, 0.5]; frames * 4];
    let clip = Clip::new("dot", v, frames, 4, vec![[0, 1, 2]], "", "dot.bin").unwrap();
    let e = Weld::Eps(0.0).apply(clip).unwrap_err();
    assert!(
        e.field.starts_with("after welding") && e.reason.contains("at least 3 vertices"),
        "{e}"
    );
}

#[test]
fn size_options_are_range_checked_before_allocation() {
    let big = 1_000_000_000;
    let synth = |f: fn(&mut SynthConfig)| {
        let mut c = SynthConfig::default();
        f(&mut c);
        c.validate().unwrap_err().field
    };
    assert_eq!(synth(|c| c.frames = 1_000_000_000), "frames");
    assert_eq!(synth(|c| c.max_vertices = 1_000_000_000), "max_vertices");
    assert_eq!(synth(|c| c.clips = 1_000_000_000), "clips");
    assert_eq!(synth(|c| c.min_vertices = usize::MAX), "max_vertices");
    for o in [
        ImportOptions { p: big, ..opts() },
        ImportOptions { frames: big, ..opts() },
        ImportOptions { stride: big, ..opts() },
        ImportOptions { p: 0, ..opts() },
    ] {
        assert!(o.validate().is_err(), "{o:?}");
    }
    let tmp = tempfile::tempdir().unwrap();
    let cfg = SynthConfig {
        clips: 1,
        ..SynthConfig::default()
    };
    let e = write_synth_windows(&cfg, &tmp.path().join("s"), big, 16, 1, None).unwrap_err();
    assert_eq!(e.field, "p");
    assert!(!tmp.path().join("s").exists(), "nothing is created for refused options");
}

/// A folder walk visits each folder and file once: a symlink cycle ends, and a file reached through a second
/// link is imported once.
#[test]
fn symlink_cycles_end_and_linked_files_import_once() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir_all(src.join("sub")).unwrap();
    formats::write_clip(&src.join("sub/a.bin"), &blob("a", 20, 1.0, 0.0)).unwrap();
    // sub/loop → src (a cycle), sub/again.bin → sub/a.bin (the same file twice), dangling.bin → nothing.
    std::os::unix::fs::symlink(&src, src.join("sub/loop")).unwrap();
    std::os::unix::fs::symlink(src.join("sub/a.bin"), src.join("sub/again.bin")).unwrap();
    std::os::unix::fs::symlink(src.join("gone.bin"), src.join("dangling.bin")).unwrap();
    let out = tmp.path().join("store");
    let report = store::import(std::slice::from_ref(&src), &out, &opts()).unwrap();
    assert_eq!(report.added, 1, "{report}");
    assert_eq!(report.rejected.len(), 1, "{report}");
    assert!(report.rejected[0].source.ends_with("dangling.bin"), "{report}");
}

/// A `.gltf` whose buffer is a file beside it imports as one clip; the buffer (a `.bin`, which on its own would be
/// read as a DyMesh pickle) is not a source of its own.
#[test]
fn gltf_external_buffers_are_not_imported_as_clips() {
    use base64::Engine;
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir_all(&src).unwrap();
    let gltf = src.join("figure.gltf");
    formats::write_clip(&gltf, &blob("figure", 20, 1.0, 0.0)).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&gltf).unwrap()).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_owned();
    let (_, data) = uri.split_once(",").unwrap();
    let raw = base64::engine::general_purpose::STANDARD.decode(data).unwrap();
    std::fs::write(src.join("figure0.bin"), raw).unwrap();
    doc["buffers"][0]["uri"] = "figure0.bin".into();
    std::fs::write(&gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    // Files of no clip format are not read, but counted by extension in the report.
    std::fs::write(src.join("skin.PNG"), b"png").unwrap();
    std::fs::write(src.join("README"), b"text").unwrap();
    std::fs::write(src.join("licence.txt"), b"text").unwrap();
    std::fs::write(src.join("notes.txt"), b"text").unwrap();
    let report = store::import(std::slice::from_ref(&src), &tmp.path().join("store"), &opts()).unwrap();
    assert_eq!(
        (report.sources, report.added, report.rejected.len()),
        (1, 1, 0),
        "{report}"
    );
    let skipped: Vec<(&str, usize)> = report.skipped.iter().map(|(e, n)| (e.as_str(), *n)).collect();
    assert_eq!(skipped, [("", 1), ("bin", 1), ("png", 1), ("txt", 2)]);
    assert!(
        report.to_string().contains("5 other files not read as clips"),
        "{report}"
    );
}
