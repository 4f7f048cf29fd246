//! The scene metrics (E8)–(E10) (docs/method.md §6.5): signed distances worked out by hand on a floor slab with a box
//! on it, the four metrics of a small clip, bad parameters, agreement with an independent numpy version
//! (`scripts/scene_metrics_reference.py`), procedural scene clips that never collide, and table 1's scene columns.

use std::path::Path;

use any4d_data::scene::Scene;
use any4d_eval::metrics::Motion;
use any4d_eval::scene_metrics::{ContactThresholds, scene_metrics, signed_distance, winding_number};

/// A floor slab (top at y = 0) with a box standing on it (x 0.3..0.7, y 0..0.5, z −0.2..0.2).
fn room() -> Scene {
    Scene::cuboid([-2.0, -1.0, -2.0], [2.0, 0.0, 2.0]).with(&Scene::cuboid([0.3, 0.0, -0.2], [0.7, 0.5, 0.2]))
}

#[test]
fn signed_distances_on_a_floor_and_a_box() {
    let s = room();
    // The scene is stored in f32: 0.3 and 0.7 are within 1e-8 of themselves.
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    // In the floor, 0.3 below its top; in the box, 0.2 from its x and z faces; above the floor, 0.3 from the box.
    for (p, want) in [
        ([0.0, -0.3, 0.0], -0.3),
        ([0.5, 0.25, 0.0], -0.2),
        ([0.0, 0.5, 0.0], 0.3),
        ([0.0, 0.01, 1.0], 0.01),
    ] {
        let got = signed_distance(&s, p);
        assert!(close(got, want), "{p:?}: {got} vs {want}");
    }
    assert!((winding_number(&s, [0.5, 0.25, 0.0]) - 1.0).abs() < 1e-9);
    assert!(winding_number(&s, [5.0, 5.0, 5.0]).abs() < 1e-9);
}

#[test]
fn a_clip_that_dips_into_the_floor_and_slides_on_it() {
    // Vertex 0 touches the floor (0.01 above it) and slides 0.05 in x every frame; vertex 1 dips 0.3 into the floor
    // at frame 1 only.
    let frames = [
        [[0.0, 0.01, 0.0], [0.0, 0.5, 0.0]],
        [[0.05, 0.01, 0.0], [0.0, -0.3, 0.0]],
        [[0.10, 0.01, 0.0], [0.0, 0.5, 0.0]],
    ];
    let flat: Vec<[f32; 3]> = frames.iter().flatten().copied().collect();
    let m = scene_metrics(Motion::new(&flat, 3, 2).unwrap(), &room(), ContactThresholds::default()).unwrap();
    assert!((m.collision_frames - 1.0 / 3.0).abs() < 1e-12, "{m:?}");
    assert!((m.collision_vertices - 1.0 / 6.0).abs() < 1e-12, "{m:?}");
    assert!((m.max_penetration - 0.3).abs() < 1e-6, "{m:?}");
    assert_eq!(m.foot_skating, 1.0, "{m:?}");
    // Sliding less than the threshold is no skating; a clip above everything touches nothing.
    let slow: Vec<[f32; 3]> = (0..3)
        .flat_map(|f| [[0.004 * f as f32, 0.01, 0.0], [0.0, 0.5, 0.0]])
        .collect();
    let m = scene_metrics(Motion::new(&slow, 3, 2).unwrap(), &room(), ContactThresholds::default()).unwrap();
    assert_eq!((m.collision_frames, m.max_penetration, m.foot_skating), (0.0, 0.0, 0.0));
    let bad = ContactThresholds {
        contact: f64::NAN,
        slide: 0.01,
    };
    assert!(scene_metrics(Motion::new(&slow, 3, 2).unwrap(), &room(), bad).is_err());
    assert!(
        scene_metrics(
            Motion::new(&slow[..2], 1, 2).unwrap(),
            &room(),
            ContactThresholds::default()
        )
        .is_err()
    );
}

#[test]
fn the_metrics_agree_with_an_independent_numpy_version() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    // 12 frames of 40 vertices on a lattice drifting through the room: some in the floor, some in the box, some
    // grazing the floor and sliding.
    let (t, n) = (12usize, 40usize);
    let motion: Vec<[f32; 3]> = (0..t)
        .flat_map(|f| {
            (0..n).map(move |v| {
                let (f, v) = (f as f32, v as f32);
                [
                    -0.6 + 0.03 * v + 0.02 * f,
                    0.4 * (0.37 * v + 0.5 * f).sin() - 0.05,
                    0.15 * (0.23 * v).cos(),
                ]
            })
        })
        .collect();
    let scene = room();
    let ours = scene_metrics(
        Motion::new(&motion, t, n).unwrap(),
        &scene,
        ContactThresholds::default(),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("input.json");
    let frames: Vec<&[[f32; 3]]> = motion.chunks(n).collect();
    let json = serde_json::json!({
        "vertices": scene.vertices, "faces": scene.faces, "motion": frames, "contact": 0.02, "slide": 0.01,
    });
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/scene_metrics_reference.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(&input)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let theirs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (name, value) in [
        ("collision_frames", ours.collision_frames),
        ("collision_vertices", ours.collision_vertices),
        ("max_penetration", ours.max_penetration),
        ("foot_skating", ours.foot_skating),
    ] {
        let want = theirs[name].as_f64().unwrap();
        assert!((value - want).abs() <= 1e-9, "{name}: {value} vs numpy {want}");
    }
    // The clip does collide and skate: the comparison is not of zeros.
    assert!(ours.collision_vertices > 0.05 && ours.max_penetration > 0.1, "{ours:?}");
    assert!(
        ours.foot_skating > 0.0 && ours.collision_frames < 1.0 + 1e-12,
        "{ours:?}"
    );
}

/// `data synth --scenes`: the ground truth of every procedural clip is free of its scene by (E8)–(E9) — in world
/// units and in the store's normalised frame — for both generators.
#[test]
fn procedural_scene_clips_never_collide() {
    use any4d_data::synth::{Family, RiggedKinds, SynthConfig, generate_scened};
    for family in [Family::Shapes, Family::Rigged(RiggedKinds::default())] {
        let cfg = SynthConfig {
            clips: 12,
            min_vertices: 256,
            max_vertices: 600,
            family,
            scenes: true,
            ..Default::default()
        };
        for i in 0..cfg.clips {
            let (clip, scene) = generate_scened(&cfg, i).unwrap();
            let scene = scene.unwrap();
            let m = scene_metrics(Motion::from_clip(&clip).unwrap(), &scene, ContactThresholds::default()).unwrap();
            assert_eq!(
                (m.collision_frames, m.max_penetration),
                (0.0, 0.0),
                "{}: {}",
                clip.id,
                clip.caption
            );
            let (norm, n) = any4d_data::preprocess::normalize(&clip);
            let m = scene_metrics(
                Motion::from_clip(&norm).unwrap(),
                &scene.normalized(&n).unwrap(),
                ContactThresholds::default(),
            )
            .unwrap();
            assert_eq!(m.collision_frames, 0.0, "{} normalised", clip.id);
        }
    }
}

/// Table 1 of a store with scenes (`data synth --scenes`) adds the scene metrics (E8)–(E10) as columns, each
/// method's mean over the items that have a scene, in the summary and its CSV.
#[test]
fn table1_of_a_store_with_scenes_reports_the_scene_metrics() {
    use any4d_data::store::write_synth_with;
    use any4d_data::synth::SynthConfig;
    use any4d_eval::methods::{MethodKind, vertex_methods};
    use any4d_eval::tables::short_horizon::{LAYOUT_SCENES, ShortHorizon};
    use any4d_eval::tables::{Items, Protocol, TableOptions, run_protocol};

    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("scenes");
    let cfg = SynthConfig {
        clips: 12,
        seed: 5,
        min_vertices: 256,
        max_vertices: 600,
        scenes: true,
        ..SynthConfig::default()
    };
    write_synth_with(&cfg, &store, 16, None).unwrap();
    let out = dir.path().join("t1");
    let mut opts = TableOptions::new(store, out.clone());
    opts.methods = vertex_methods(&[MethodKind::Lerp]).unwrap();
    opts.split = any4d_eval::protocol::EvalSplit::All;
    opts.progress = false;
    opts.export_items = 1;
    let table1 = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            clips: 2,
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    let report = run_protocol(&table1, &opts).unwrap();
    assert_eq!(report.title, LAYOUT_SCENES.title);
    let col = |header: &str| LAYOUT_SCENES.columns.iter().position(|c| c.header == header).unwrap();
    for r in &report.rows {
        for h in [
            "collision frames %",
            "collision vertices %",
            "max penetration ×100",
            "foot skating %",
        ] {
            let v = r.values[col(h)].mean;
            assert!(v.is_finite() && (0.0..=100.0).contains(&v), "{h}: {v}");
        }
    }
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert!(csv.contains("scene_collision_frames_mean"), "{csv}");
    // The exported item's viewer pages draw its scene.
    let page = std::fs::read_to_string(out.join("view").join("item000_k0_seed42.html")).unwrap();
    assert!(page.contains("\"scene\":{\"faces\""), "no scene on the item's page");
}
