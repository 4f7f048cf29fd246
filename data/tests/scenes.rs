//! Scenes in the store (docs/method.md §6.5): a clip imported with `<name>.scene.obj` beside it keeps the scene in
//! every window, normalised with the window; a store without scenes joined by such a source keeps its clips; a
//! record whose scene section lies, or a header with flags this build does not know, is refused by name.

use std::path::Path;

use any4d_data::Clip;
use any4d_data::formats;
use any4d_data::preprocess::VertexFilter;
use any4d_data::scene::Scene;
use any4d_data::store::{self, ImportOptions, Store, check_index, read_index, verify_store};

/// A wave over a 6 × 6 sheet, 8 frames, far from the origin (so normalisation moves it).
fn sheet(id: &str) -> Clip {
    let n = 36;
    let vertices = (0..8)
        .flat_map(|f| {
            (0..n).map(move |v| {
                let (x, z) = ((v % 6) as f32, (v / 6) as f32);
                [10.0 + x, 2.0 + 0.3 * (x + 0.5 * f as f32).sin(), -4.0 + z]
            })
        })
        .collect();
    let faces = (0..5u32)
        .flat_map(|r| {
            (0..5u32).flat_map(move |c| {
                let i = r * 6 + c;
                [[i, i + 6, i + 1], [i + 1, i + 6, i + 7]]
            })
        })
        .collect();
    Clip::new(id, vertices, 8, n, faces, "a sheet waving", "test").unwrap()
}

fn opts() -> ImportOptions {
    ImportOptions {
        filter: VertexFilter { min: 3, max: 1024 },
        frames: 4,
        stride: 4,
        p: 8,
        ..Default::default()
    }
}

fn write_obj(path: &Path, s: &Scene) {
    let mut text = String::new();
    for v in &s.vertices {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for f in &s.faces {
        text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(path, text).unwrap();
}

/// The floor slab every test puts `wave.bin` on.
fn floor() -> Scene {
    Scene::cuboid([8.0, 0.0, -6.0], [17.0, 1.5, 3.0])
}

/// `dir/src` with `wave.bin` and `wave.scene.obj` (the floor), imported into `dir/store`, which is returned.
fn scene_store(dir: &Path) -> std::path::PathBuf {
    let src = dir.join("src");
    std::fs::create_dir(&src).unwrap();
    formats::write_clip(&src.join("wave.bin"), &sheet("wave")).unwrap();
    write_obj(&src.join("wave.scene.obj"), &floor());
    let out = dir.join("store");
    store::import(std::slice::from_ref(&src), &out, &opts()).unwrap();
    out
}

#[test]
fn an_imported_scene_travels_with_every_window_normalised_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    formats::write_clip(&src.join("wave.bin"), &sheet("wave")).unwrap();
    let floor = floor();
    write_obj(&src.join("wave.scene.obj"), &floor);
    let out = dir.path().join("store");
    let report = store::import(std::slice::from_ref(&src), &out, &opts()).unwrap();
    // The scene file is read with its clip: not a source, not a skipped file, not an OBJ folder.
    assert_eq!(
        (report.sources, report.rejected.len(), report.added),
        (1, 0, 2),
        "{report}"
    );
    assert!(report.skipped.is_empty(), "{report}");
    let s = Store::open(&out).unwrap();
    assert!(s.has_scenes());
    for i in 0..s.len() {
        let c = s.get(i).unwrap();
        let scene = c.scene.expect("every window carries the scene");
        assert_eq!(scene, floor.normalized(&c.normalization).unwrap(), "window {i}");
    }
    check_index(&s, &read_index(&out).unwrap()).unwrap();
    assert!(verify_store(&out).unwrap().problems.is_empty());
    // A second source without a scene joins the store: its windows have none.
    let more = dir.path().join("more");
    std::fs::create_dir(&more).unwrap();
    formats::write_clip(&more.join("calm.bin"), &sheet("calm")).unwrap();
    store::import(std::slice::from_ref(&more), &out, &opts()).unwrap();
    let s = Store::open(&out).unwrap();
    let with: usize = (0..s.len()).filter(|&i| s.get(i).unwrap().scene.is_some()).count();
    assert_eq!((s.len(), with), (4, 2));
    assert!(verify_store(&out).unwrap().problems.is_empty());
}

#[test]
fn a_store_without_scenes_joined_by_a_source_with_one_keeps_its_clips() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::fs::create_dir(&a).unwrap();
    std::fs::create_dir(&b).unwrap();
    formats::write_clip(&a.join("calm.bin"), &sheet("calm")).unwrap();
    formats::write_clip(&b.join("wave.bin"), &sheet("wave")).unwrap();
    write_obj(&b.join("wave.scene.obj"), &floor());
    let out = dir.path().join("store");
    store::import(std::slice::from_ref(&a), &out, &opts()).unwrap();
    let before = Store::open(&out).unwrap();
    assert!(!before.has_scenes());
    let kept: Vec<_> = (0..before.len()).map(|i| before.get(i).unwrap().clip).collect();
    store::import(std::slice::from_ref(&b), &out, &opts()).unwrap();
    let after = Store::open(&out).unwrap();
    assert!(after.has_scenes());
    let calm: Vec<_> = (0..after.len())
        .map(|i| after.get(i).unwrap())
        .filter(|c| c.clip.source.contains("calm"))
        .collect();
    assert_eq!(calm.iter().map(|c| c.clip.clone()).collect::<Vec<_>>(), kept);
    assert!(calm.iter().all(|c| c.scene.is_none()));
    check_index(&after, &read_index(&out).unwrap()).unwrap();
}

#[test]
fn lying_scene_sections_and_unknown_flags_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = scene_store(dir.path());
    let bin = out.join("clips.bin");
    let good = std::fs::read(&bin).unwrap();
    let s = Store::open(&out).unwrap();
    let raw = s.raw(0).unwrap();
    // The scene section's counts sit right after the 16-byte normalisation: 8 vertices, 12 faces.
    let record_at = good.windows(raw.len()).position(|w| w == raw.as_slice()).unwrap();
    let counts_at = record_at + raw.len() - (8 + 8 * 12 + 12 * 12);
    assert_eq!(&good[counts_at..counts_at + 8], &[8, 0, 0, 0, 12, 0, 0, 0]);
    let mut lying = good.clone();
    lying[counts_at..counts_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(&bin, &lying).unwrap();
    let e = Store::open(&out).unwrap().get(0).unwrap_err();
    assert!(e.field.contains("scene vertices"), "{e}");
    let mut face = good.clone();
    let last_face = counts_at + 8 + 8 * 12;
    face[last_face..last_face + 4].copy_from_slice(&99u32.to_le_bytes());
    std::fs::write(&bin, &face).unwrap();
    let e = Store::open(&out).unwrap().get(0).unwrap_err();
    assert!(e.field.contains("scene") && e.reason.contains("indexes past"), "{e}");
    let mut flags = good.clone();
    flags[20..24].copy_from_slice(&2u32.to_le_bytes());
    std::fs::write(&bin, &flags).unwrap();
    let e = Store::open(&out).unwrap_err();
    assert!(e.field.contains("flags"), "{e}");
}

/// numpy alone reads a store with scenes (`scripts/read_any4d.py store`).
#[test]
fn numpy_reads_a_store_with_scenes() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = scene_store(dir.path());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/read_any4d.py");
    let run = std::process::Command::new("python3")
        .arg(&script)
        .arg("store")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{stdout}{}", String::from_utf8_lossy(&run.stderr));
    assert!(
        stdout.contains("T 4 P 8 clips 2") && stdout.contains("scenes 2"),
        "{stdout}"
    );
}

/// `data synth --scenes`: every procedural clip carries its scene, normalised with its window, and a caption that
/// names the furniture; the clips themselves are those of the same run without scenes (another source each, so
/// both kinds can share a store).
#[test]
fn procedural_clips_in_scenes_carry_them_and_equal_the_plain_clips() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = any4d_data::synth::SynthConfig {
        clips: 6,
        max_vertices: 1024,
        scenes: true,
        ..Default::default()
    };
    let out = dir.path().join("store");
    store::write_synth_with(&cfg, &out, 8, None).unwrap();
    let plain_cfg = any4d_data::synth::SynthConfig {
        scenes: false,
        ..cfg.clone()
    };
    let plain_out = dir.path().join("plain");
    store::write_synth_with(&plain_cfg, &plain_out, 8, None).unwrap();
    let (s, plain) = (Store::open(&out).unwrap(), Store::open(&plain_out).unwrap());
    assert!(s.has_scenes() && !plain.has_scenes());
    assert_eq!(s.len(), 6);
    let phrases = ["pillar", "wall", "ceiling", "box", "table"];
    for i in 0..s.len() {
        let (c, p) = (s.get(i).unwrap(), plain.get(i).unwrap());
        assert_eq!(c.clip.vertices, p.clip.vertices, "clip {i}");
        assert!(c.clip.caption.starts_with(&p.clip.caption), "{}", c.clip.caption);
        assert!(phrases.iter().any(|w| c.clip.caption.contains(w)), "{}", c.clip.caption);
        let (scene, raw) = (
            c.scene.unwrap(),
            any4d_data::synth::generate_scened(&cfg, i).unwrap().1.unwrap(),
        );
        assert_eq!(scene, raw.normalized(&c.normalization).unwrap(), "clip {i}");
    }
    assert!(verify_store(&out).unwrap().problems.is_empty());
    let summary = any4d_data::inspect::summarize(&out).unwrap();
    assert_eq!(summary.scenes, Some(6));
    assert!(
        summary.to_table().contains("6 of 6 clips move in a scene"),
        "{}",
        summary.to_table()
    );
    assert_eq!(any4d_data::inspect::summarize(&plain_out).unwrap().scenes, None);
}

/// A glTF file whose one node moves (a triangle sliding along x) beside a still box (its node placed 1 below the
/// origin): the box is the file's scene, placed by its node, and an import stores it with every window.
#[test]
fn a_gltf_files_still_meshes_are_its_scene() {
    use base64::Engine;
    let floats = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let floor = Scene::cuboid([-2.0, -0.5, -2.0], [2.0, 0.0, 2.0]);
    let mut buf = floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    buf.extend(floats(&floor.vertices.concat()));
    floor.faces.iter().flatten().for_each(|i| buf.extend(i.to_le_bytes()));
    buf.extend(floats(&[0.0, 1.0]));
    buf.extend(floats(&[0.0, 0.0, 0.0, 3.0, 0.0, 0.0]));
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&buf)
    );
    let view = |offset: usize, len: usize| serde_json::json!({"buffer": 0, "byteOffset": offset, "byteLength": len});
    let json = serde_json::json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": buf.len(), "uri": uri}],
        "bufferViews": [view(0, 36), view(36, 96), view(132, 144), view(276, 8), view(284, 24)],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 8, "type": "VEC3", "min": [-2, -0.5, -2], "max": [2, 0, 2]},
            {"bufferView": 2, "componentType": 5125, "count": 36, "type": "SCALAR"},
            {"bufferView": 3, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
            {"bufferView": 4, "componentType": 5126, "count": 2, "type": "VEC3"}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}}]},
            {"primitives": [{"attributes": {"POSITION": 1}, "indices": 2}]}
        ],
        "nodes": [{"mesh": 0}, {"mesh": 1, "translation": [0, -1, 0]}],
        "scenes": [{"nodes": [0, 1]}],
        "scene": 0,
        "animations": [{
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            "samplers": [{"input": 3, "output": 4}]
        }]
    });
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    let file = src.join("slide.gltf");
    std::fs::write(&file, serde_json::to_vec(&json).unwrap()).unwrap();
    let scene = formats::gltf::static_scene(&file).unwrap().expect("the still box");
    let placed: Vec<[f32; 3]> = floor.vertices.iter().map(|v| [v[0], v[1] - 1.0, v[2]]).collect();
    assert_eq!((scene.vertices, scene.faces.clone()), (placed, floor.faces.clone()));
    let out = dir.path().join("store");
    let report = store::import(std::slice::from_ref(&src), &out, &opts()).unwrap();
    assert!(report.added > 0, "{report}");
    let s = Store::open(&out).unwrap();
    assert!(s.has_scenes());
    assert!((0..s.len()).all(|i| s.get(i).unwrap().scene.is_some_and(|sc| sc.faces == floor.faces)));
    // A still mesh indexing past its vertices is an error naming it (the import then rejects the file).
    let mut broken = json.clone();
    broken["accessors"][2]["count"] = serde_json::json!(36);
    broken["meshes"][1]["primitives"][0]["attributes"]["POSITION"] = serde_json::json!(0);
    std::fs::write(&file, serde_json::to_vec(&broken).unwrap()).unwrap();
    let e = formats::gltf::static_scene(&file).unwrap_err();
    assert!(e.field.contains("meshes[1]") && e.reason.contains("of 3"), "{e}");
    // Without the still node there is no scene.
    let mut alone = json.clone();
    alone["nodes"] = serde_json::json!([{"mesh": 0}]);
    alone["scenes"] = serde_json::json!([{"nodes": [0]}]);
    std::fs::write(&file, serde_json::to_vec(&alone).unwrap()).unwrap();
    assert!(formats::gltf::static_scene(&file).unwrap().is_none());
}
