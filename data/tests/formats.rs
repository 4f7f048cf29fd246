//! Clip file formats against fixtures made by `scripts/make_fixtures.py` (real pickle + numpy) (docs/method.md §2.1).

use std::path::{Path, PathBuf};
use std::process::Command;

use any4d_data::Clip;
use any4d_data::formats::dymesh_bin::{read_bin, write_bin};
use any4d_data::formats::gltf::{GltfReadOptions, read_gltf, write_gltf};
use any4d_data::formats::obj::{read_obj_seq, write_obj_seq};
use any4d_data::formats::skeletal::{ReadOptions, TakeSel};
use any4d_data::formats::{self, read_clip, write_clip, write_clip_at};

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(rel)
}

/// A small moving clip with coordinates that are not round numbers.
fn sample_clip() -> Clip {
    let (t, n) = (4, 5);
    let v = (0..t * n)
        .map(|i| {
            let (f, k) = ((i / n) as f32, (i % n) as f32);
            [
                0.1 * k + 0.013 * f,
                (k * 0.7).sin() - f * 0.25,
                1.0 / (k + 3.0) + f * f * 0.01,
            ]
        })
        .collect();
    Clip::new(
        "sample",
        v,
        t,
        n,
        vec![[0, 1, 2], [0, 2, 3], [3, 4, 0]],
        "a thing wiggles",
        "mem",
    )
    .unwrap()
}

fn assert_close(a: &[[f32; 3]], b: &[[f32; 3]], tol: f32) {
    assert_eq!(a.len(), b.len());
    for (i, (p, q)) in a.iter().zip(b).enumerate() {
        for c in 0..3 {
            assert!((p[c] - q[c]).abs() <= tol, "row {i}: {p:?} vs {q:?}");
        }
    }
}

#[test]
fn good_bin_fixtures_match_numpy_exactly() {
    let text = std::fs::read_to_string(fixture("bin/expected.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases = expected.as_object().unwrap();
    assert_eq!(cases.len(), 10);
    for (name, want) in cases {
        let path = fixture(&format!("bin/{name}.bin"));
        let clip = read_bin(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let shape: Vec<usize> = want["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect();
        let flat: Vec<f32> = want["vertices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect();
        let faces: Vec<u32> = want["faces"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as u32)
            .collect();
        assert_eq!((clip.frames, clip.n_vertices), (shape[0], shape[1]), "{name}");
        assert_eq!(
            clip.vertices.iter().flatten().copied().collect::<Vec<_>>(),
            flat,
            "{name}"
        );
        assert_eq!(
            clip.faces.iter().flatten().copied().collect::<Vec<_>>(),
            faces,
            "{name}"
        );
        assert_eq!(clip.caption, want["caption"].as_str().unwrap(), "{name}");
        assert_eq!(
            (clip.id.as_str(), clip.source.as_str()),
            (name.as_str(), path.display().to_string().as_str())
        );
    }
    // float64 0.1 rounds to float32 as numpy does, and the special captions survive.
    let c = read_bin(&fixture("bin/p2_f64.bin")).unwrap();
    assert_eq!(
        c.vertices[1],
        [0.1f64 as f32, (0.1f64 + 0.01) as f32, (0.1f64 + 0.02) as f32]
    );
    assert_eq!(read_bin(&fixture("bin/no_caption.bin")).unwrap().caption, " ");
    assert_eq!(read_bin(&fixture("bin/empty_caption.bin")).unwrap().caption, "");
    assert_eq!(
        read_bin(&fixture("bin/bytes_caption.bin")).unwrap().caption,
        "café spins"
    );
}

#[test]
fn bad_bin_fixtures_name_path_and_field() {
    let cases = [
        ("no_vertices", "vertices", "missing key"),
        ("no_faces", "faces", "missing key"),
        ("vertices_rank2", "vertices", "shape [4, 3]"),
        ("vertices_last_dim4", "vertices", "shape [2, 4, 4]"),
        ("faces_rank1", "faces", "shape [6]"),
        ("nan_coords", "vertices", "non-finite"),
        ("face_out_of_range", "faces", "indexes past"),
        ("face_negative", "faces", "index -1"),
        ("zero_frames", "vertices", "zero frames"),
        ("caption_not_utf8", "caption", "UTF-8"),
        ("caption_int", "caption", "is a int"),
        ("not_a_dict", "pickle", "list"),
        ("truncated", "pickle", "truncated"),
        ("not_pickle", "pickle", "stack underflow"),
        ("hostile_os_system", "pickle", "`posix.system` is not allowed"),
        ("hostile_builtins_eval", "pickle", "`builtins.eval` is not allowed"),
    ];
    for (name, field, reason) in cases {
        let path = fixture(&format!("bin/bad_{name}.bin"));
        let e = read_bin(&path).expect_err(name);
        assert_eq!(e.path, path.display().to_string(), "{name}");
        assert_eq!(e.field, field, "{name}: {e}");
        assert!(e.reason.contains(reason), "{name}: {e}");
    }
}

#[test]
fn hostile_pickles_never_run() {
    let marks = ["/tmp/any4d_fixture_pwned_os_system", "/tmp/any4d_fixture_pwned_eval"];
    for m in marks {
        assert!(
            !Path::new(m).exists(),
            "{m} exists before the test; remove it and rerun"
        );
    }
    for name in ["hostile_os_system", "hostile_builtins_eval"] {
        assert!(read_bin(&fixture(&format!("bin/bad_{name}.bin"))).is_err());
        assert!(read_clip(&fixture(&format!("bin/bad_{name}.bin"))).is_err());
    }
    for m in marks {
        assert!(!Path::new(m).exists(), "{m} appeared: a hostile pickle was executed");
    }
}

#[test]
fn write_bin_round_trips_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample.bin");
    let clip = sample_clip();
    write_bin(&path, &clip).unwrap();
    let back = read_bin(&path).unwrap();
    assert_eq!(
        (back.vertices, back.faces, back.caption, back.frames),
        (clip.vertices, clip.faces, clip.caption, clip.frames)
    );
}

#[test]
fn python_reads_written_bin() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample.bin");
    write_bin(&path, &sample_clip()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/check_bin.py");
    let out = Command::new("python3").arg(&script).arg(&path).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("vertices ndarray float32 (4, 5, 3) C"), "{stdout}");
    assert!(stdout.contains("faces ndarray int64 (3, 3) C"), "{stdout}");
    assert!(stdout.contains("caption str 'a thing wiggles'"), "{stdout}");
    let v0 = sample_clip().vertices[0].map(|x| x as f64);
    assert!(
        stdout.contains(&format!("vertices[0,0] [{:?}, {:?}, {:?}]", v0[0], v0[1], v0[2])),
        "{stdout}"
    );
}

#[test]
fn obj_sequence_reads_in_natural_order() {
    let clip = read_obj_seq(&fixture("obj/quad_seq")).unwrap();
    assert_eq!((clip.frames, clip.n_vertices, clip.id.as_str()), (3, 4, "quad_seq"));
    assert_eq!(clip.faces, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(clip.caption, "a quad rises");
    // frame_1, frame_2, frame_10 lift z by 0, 0.5, 1 (plus 0.25 x).
    assert_eq!(clip.frame(1)[1], [1.0, 0.0, 0.75]);
    assert_eq!(clip.frame(2)[3], [0.0, 1.0, 1.0]);
}

#[test]
fn bad_obj_sequences_name_file_and_line() {
    let e = read_obj_seq(&fixture("obj/bad_vertex_count")).unwrap_err();
    assert!(e.path.ends_with("f1.obj") && e.field == "vertices", "{e}");
    let e = read_obj_seq(&fixture("obj/bad_line")).unwrap_err();
    assert!(
        e.path.ends_with("a.obj") && e.field == "line 3" && e.reason.contains("`one`"),
        "{e}"
    );
    let e = read_obj_seq(&fixture("gltf")).unwrap_err();
    assert_eq!(e.field, "frames");
}

#[test]
fn obj_round_trip_and_no_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    let clip = sample_clip();
    write_obj_seq(&seq, &clip).unwrap();
    let back = read_obj_seq(&seq).unwrap();
    assert_eq!(
        (back.vertices, back.faces, back.caption),
        (clip.vertices.clone(), clip.faces.clone(), clip.caption.clone())
    );
    assert_eq!(write_obj_seq(&seq, &clip).unwrap_err().field, "frames");
}

#[test]
fn gltf_morph_fixture_bakes_weights() {
    let clip = read_gltf(&fixture("gltf/morph_square.gltf"), &GltfReadOptions::default()).unwrap();
    assert_eq!((clip.frames, clip.n_vertices), (31, 4));
    assert_eq!(clip.faces, vec![[0, 1, 2], [0, 2, 3]]);
    let square = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let moved = |d: [f32; 3]| square.map(|p: [f32; 3]| [p[0] + d[0], p[1] + d[1], p[2] + d[2]]);
    assert_close(clip.frame(0), &square, 1e-6);
    assert_close(clip.frame(6), &moved([0.0, 0.0, 0.4]), 1e-6); // t = 0.2: w = (0.4, 0)
    assert_close(clip.frame(15), &moved([0.0, 0.0, 1.0]), 1e-6); // t = 0.5: w = (1, 0)
    assert_close(clip.frame(24), &moved([1.2, 0.0, 0.4]), 1e-6); // t = 0.8: w = (0.4, 0.6)
    assert_close(clip.frame(30), &moved([2.0, 0.0, 0.0]), 1e-6);
    let opts = GltfReadOptions {
        fps: 10.0,
        max_frames: Some(5),
        mesh: Some(0),
        take: 0,
    };
    assert_eq!(read_gltf(&fixture("gltf/morph_square.gltf"), &opts).unwrap().frames, 5);
    let opts = GltfReadOptions {
        mesh: Some(3),
        ..GltfReadOptions::default()
    };
    assert_eq!(
        read_gltf(&fixture("gltf/morph_square.gltf"), &opts).unwrap_err().field,
        "meshes"
    );
}

#[test]
fn gltf_skin_fixture_bakes_joints() {
    let clip = read_gltf(&fixture("gltf/skin_strip.gltf"), &GltfReadOptions::default()).unwrap();
    assert_eq!((clip.frames, clip.n_vertices, clip.faces.len()), (31, 6, 4));
    let rest = [
        [-0.5, 0.0, 0.0],
        [0.5, 0.0, 0.0],
        [-0.5, 1.0, 0.0],
        [0.5, 1.0, 0.0],
        [-0.5, 2.0, 0.0],
        [0.5, 2.0, 0.0],
    ];
    assert_close(clip.frame(0), &rest, 1e-6);
    // t = 14/30 < 0.5: the STEP translation of the root joint has not happened; bottom row still at rest.
    assert_close(&clip.frame(14)[..2], &rest[..2], 1e-6);
    // t = 1: root moved by x + 1, joint 1 (at y = 1) turned 90° about z; middle row averages both joints.
    let end = [
        [0.5, 0.0, 0.0],
        [1.5, 0.0, 0.0],
        [0.75, 0.75, 0.0],
        [1.25, 1.25, 0.0],
        [0.0, 0.5, 0.0],
        [0.0, 1.5, 0.0],
    ];
    assert_close(clip.frame(30), &end, 1e-5);
}

/// A vertex whose weights are all 0 (castle-game-engine's soldier has them) follows the first joint of its
/// JOINTS_0 entry, as three.js's loader normalises it; a first joint outside the skin is still refused.
#[test]
fn gltf_vertex_without_weight_follows_its_first_joint() {
    use base64::Engine as _;
    let path = fixture("gltf/skin_strip.gltf");
    let whole = read_gltf(&path, &GltfReadOptions::default()).unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap();
    let (head, data) = uri.split_once(',').unwrap();
    let engine = base64::engine::general_purpose::STANDARD;
    let bytes = engine.decode(data).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let write = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut b = bytes.clone();
        edit(&mut b);
        let mut doc = doc.clone();
        doc["buffers"][0]["uri"] = format!("{head},{}", engine.encode(&b)).into();
        let p = dir.path().join("zero.gltf");
        std::fs::write(&p, serde_json::to_vec(&doc).unwrap()).unwrap();
        p
    };
    // Vertex 4 (joints [0, 1, 0, 0], weight 1 on joint 1) loses its weights: bytes 120 + 16·4 of WEIGHTS_0.
    let zero_weights = |b: &mut Vec<u8>| b[184..200].fill(0);
    let got = read_gltf(&write(&zero_weights), &GltfReadOptions::default()).unwrap();
    let untouched: Vec<usize> = (0..6).filter(|&v| v != 4).collect();
    for f in [0, 30] {
        for &v in &untouched {
            assert_eq!(got.frame(f)[v], whole.frame(f)[v], "frame {f} vertex {v}");
        }
    }
    // On joint 0 alone it moves with the root (x + 1) and not with joint 1's turn.
    assert_close(&got.frame(30)[4..5], &[[0.5, 2.0, 0.0]], 1e-5);
    // Its first joint index (JOINTS_0 byte 96 + 4·4) past the skin's two joints: refused naming the vertex.
    let bad = |b: &mut Vec<u8>| {
        zero_weights(b);
        b[112] = 7;
    };
    let e = read_gltf(&write(&bad), &GltfReadOptions::default()).unwrap_err();
    assert!(e.reason.contains("vertex 4 has no joint weight"), "{e}");
}

/// One animation per channel (COLLADA2GLTF's layout: one per joint) bakes as the single animation does; two
/// animations of the same channel are alternatives, and the first is read.
#[test]
fn gltf_animations_on_disjoint_channels_play_together() {
    let path = fixture("gltf/skin_strip.gltf");
    let whole = read_gltf(&path, &GltfReadOptions::default()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let anim = doc["animations"][0].clone();
    let channels = anim["channels"].as_array().unwrap().clone();
    assert!(channels.len() >= 2, "the fixture moves two joints");
    let split: Vec<serde_json::Value> = channels
        .iter()
        .map(|ch| {
            let sampler = anim["samplers"][ch["sampler"].as_u64().unwrap() as usize].clone();
            let mut ch = ch.clone();
            ch["sampler"] = 0.into();
            serde_json::json!({ "channels": [ch], "samplers": [sampler] })
        })
        .collect();
    doc["animations"] = split.clone().into();
    let dir = tempfile::tempdir().unwrap();
    let split_path = dir.path().join("split.gltf");
    std::fs::write(&split_path, serde_json::to_vec(&doc).unwrap()).unwrap();
    let got = read_gltf(&split_path, &GltfReadOptions::default()).unwrap();
    assert_eq!((got.frames, &got.vertices), (whole.frames, &whole.vertices));
    let takes = formats::list_takes(&split_path).unwrap().unwrap();
    assert_eq!(takes.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["all"]);
    // The first channel twice: alternatives (as Blender writes one animation per action), so each animation is a
    // take of its own, named after it, and picked by index or name.
    let mut named = split[0].clone();
    named["name"] = "wave".into();
    doc["animations"] = serde_json::json!([split[0], named, split[1]]);
    std::fs::write(&split_path, serde_json::to_vec(&doc).unwrap()).unwrap();
    let takes = formats::list_takes(&split_path).unwrap().unwrap();
    let names: Vec<&str> = takes.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["animation0", "wave", "animation2"]);
    let read = |take: TakeSel| {
        let opts = ReadOptions {
            take,
            ..ReadOptions::default()
        };
        formats::read_take(&split_path, &opts).unwrap()
    };
    let first = read(TakeSel::First);
    assert_ne!(first.clip.vertices, whole.vertices);
    assert_eq!(first.take.unwrap().name, "animation0");
    assert_eq!(read(TakeSel::Name("wave".into())).clip.vertices, first.clip.vertices);
    let third = read(TakeSel::Index(2));
    assert_ne!(third.clip.vertices, first.clip.vertices);
    assert_eq!(third.clip.frames, takes[2].frames);
    // An import makes a clip of every take.
    let report = any4d_data::store::import(
        std::slice::from_ref(&split_path),
        &dir.path().join("store"),
        &any4d_data::store::ImportOptions {
            filter: any4d_data::preprocess::VertexFilter { min: 3, max: 1024 },
            frames: 2,
            p: 4,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!((report.rejected.len(), report.sources), (0, 1), "{report}");
    assert!(report.added >= 3, "{report}");
}

#[test]
fn gltf_without_animation_is_an_error() {
    let e = read_gltf(&fixture("gltf/static_square.gltf"), &GltfReadOptions::default()).unwrap_err();
    assert_eq!((e.field.as_str(), e.reason.as_str()), ("animations", "no animation"));
}

#[test]
fn gltf_and_glb_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let clip = sample_clip();
    for name in ["sample.gltf", "sample.glb"] {
        let path = dir.path().join(name);
        write_gltf(&path, &clip, 24.0).unwrap();
        let opts = GltfReadOptions {
            fps: 24.0,
            ..GltfReadOptions::default()
        };
        let back = read_gltf(&path, &opts).unwrap();
        assert_eq!(
            (back.frames, back.n_vertices, &back.faces, back.caption.as_str()),
            (4, 5, &clip.faces, "a thing wiggles"),
            "{name}"
        );
        assert_close(&back.vertices, &clip.vertices, 1e-6);
    }
}

/// Extensions a file may require that change no vertex (lights, materials, texture transforms, texture formats) are
/// read through; one that does (Draco-compressed geometry) is refused, naming it.
#[test]
fn gltf_required_extensions_that_move_no_vertex_are_read_through() {
    let dir = tempfile::tempdir().unwrap();
    let clip = sample_clip();
    let plain = dir.path().join("plain.gltf");
    write_gltf(&plain, &clip, 24.0).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&plain).unwrap()).unwrap();
    let harmless = ["KHR_lights_punctual", "KHR_materials_unlit", "KHR_texture_transform"];
    doc["extensionsUsed"] = serde_json::json!(harmless);
    doc["extensionsRequired"] = serde_json::json!(harmless);
    doc["extensions"] = serde_json::json!({
        "KHR_lights_punctual": { "lights": [{ "type": "point", "color": [1.0, 0.9, 0.8], "intensity": 3.0 }] }
    });
    let lit = dir.path().join("lit.gltf");
    std::fs::write(&lit, serde_json::to_vec(&doc).unwrap()).unwrap();
    let opts = GltfReadOptions {
        fps: 24.0,
        ..GltfReadOptions::default()
    };
    let (a, b) = (read_gltf(&plain, &opts).unwrap(), read_gltf(&lit, &opts).unwrap());
    assert_eq!((a.frames, &a.vertices, &a.faces), (b.frames, &b.vertices, &b.faces));

    doc["extensionsUsed"] = serde_json::json!(["KHR_draco_mesh_compression"]);
    doc["extensionsRequired"] = serde_json::json!(["KHR_draco_mesh_compression"]);
    let draco = dir.path().join("draco.gltf");
    std::fs::write(&draco, serde_json::to_vec(&doc).unwrap()).unwrap();
    let e = read_gltf(&draco, &opts).unwrap_err();
    assert!(e.to_string().contains("extensionsRequired"), "{e}");
}

#[test]
fn read_and_write_clip_dispatch_by_path() {
    let dir = tempfile::tempdir().unwrap();
    let clip = sample_clip();
    for name in ["c.bin", "c.glb", "c.gltf", "c_frames"] {
        let path = dir.path().join(name);
        write_clip(&path, &clip).unwrap();
        let back = read_clip(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((back.frames, &back.faces), (clip.frames, &clip.faces), "{name}");
        assert_close(&back.vertices, &clip.vertices, 1e-6);
    }
    assert_eq!(read_clip(&dir.path().join("c.blend")).unwrap_err().field, "format");
}

#[test]
fn a_take_rate_travels_into_gltf_and_bad_rates_fall_back_to_the_default() {
    let dir = tempfile::tempdir().unwrap();
    let clip = sample_clip();
    // Four frames at 10 fps last 0.3 s: read back at the reader's 30 fps, that is 10 frames (at 30 fps, 4).
    let frames_at = |fps: Option<f32>| {
        let path = dir.path().join("c.glb");
        write_clip_at(&path, &clip, fps).unwrap();
        read_gltf(&path, &GltfReadOptions::default()).unwrap().frames
    };
    assert_eq!(frames_at(Some(10.0)), 10);
    for fallback in [None, Some(0.0), Some(f32::NAN), Some(-10.0), Some(f32::INFINITY)] {
        assert_eq!(frames_at(fallback), 4, "{fallback:?}");
    }
}

/// The Khronos sample files that Debian's `assimp-testmodels` installs; not copied into the repository.
#[test]
fn system_gltf_samples_when_installed() {
    let root = Path::new("/usr/share/assimp/models/glTF2");
    let files = [
        "glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf",
        "simple_skin/simple_skin.gltf",
    ];
    if !root.join(files[0]).exists() {
        println!("skipped: assimp-testmodels not installed (apt-get install assimp-testmodels)");
        return;
    }
    for f in files {
        let clip = read_gltf(&root.join(f), &GltfReadOptions::default()).unwrap_or_else(|e| panic!("{f}: {e}"));
        let moved = (1..clip.frames).map(|k| {
            clip.frame(k)
                .iter()
                .zip(clip.frame(0))
                .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f32::max))
                .fold(0.0, f32::max)
        });
        let max_move = moved.fold(0.0, f32::max);
        println!(
            "{f}: {} frames, {} vertices, max displacement from frame 0 {max_move}",
            clip.frames, clip.n_vertices
        );
        assert!(clip.frames > 10 && max_move > 0.1, "{f}");
    }
}

#[test]
fn a_quake_player_imports_as_one_object_from_its_lower_body() {
    let dir = tempfile::tempdir().unwrap();
    let sarge = dir.path().join("sarge");
    std::fs::create_dir(&sarge).unwrap();
    formats::md3::testing::write_test_player(&sarge);
    let store = dir.path().join("store");
    let report = any4d_data::store::import(
        std::slice::from_ref(&sarge),
        &store,
        &any4d_data::store::ImportOptions {
            filter: any4d_data::preprocess::VertexFilter { min: 3, max: 1024 },
            frames: 2,
            p: 3,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!((report.rejected.len(), report.sources), (0, 2), "{report}");
    // The cfg's one-frame poses are listed as such, not dropped unseen.
    assert!(
        report.poses.iter().any(|p| p.ends_with("lower.md3#TORSO_STAND")),
        "{report}"
    );
    assert!(
        report.to_string().contains("one-frame animations not read as takes"),
        "{report}"
    );
    assert_eq!(
        formats::md3::one_frame_takes(&sarge.join("lower.md3")).unwrap().len(),
        report.poses.len()
    );
    let store = any4d_data::store::Store::open(&store).unwrap();
    let mut captions: Vec<String> = (0..store.len())
        .map(|i| store.get(i).unwrap().clip)
        .filter(|c| c.source.contains("lower.md3"))
        .map(|c| c.caption)
        .collect();
    captions.dedup();
    assert!(captions.contains(&"a sarge walking".to_owned()), "{captions:?}");
    assert!(captions.iter().all(|c| c.starts_with("a sarge")), "{captions:?}");
}
