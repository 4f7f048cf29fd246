//! `any4d eval metrics` end to end (docs/method.md §6.1–§6.2): runs the built binary on clip files written with
//! `any4d_data::formats::write_clip`, checks the JSON and table outputs and the errors on malformed input; and the
//! `eval run` flags that a saved manifest overrides.

use std::path::{Path, PathBuf};
use std::process::Output;

use any4d_data::Clip;
use any4d_data::formats::write_clip;
use polars::prelude::{ParquetReader, SerReader};

mod common;
use common::any4d;

const FRAMES: usize = 16;

/// Ground truth: `n` vertices whose frame 0 spans [−1, 1]³ with centre 0 (so (D1)–(D3) is the identity), moving
/// along y; the prediction is the same motion shifted by (d, 0, 0).
fn clips(n: usize, d: f32) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let corner = |i: usize| -> [f32; 3] {
        let s = |b: usize| if (i >> b) & 1 == 1 { 1.0 } else { -1.0 };
        [s(0), s(1), s(2)]
    };
    let gt: Vec<[f32; 3]> = (0..FRAMES)
        .flat_map(|f| {
            (0..n)
                .map(corner)
                .map(move |p| [p[0], p[1] + 0.01 * (f * f) as f32, p[2]])
        })
        .collect();
    let pred = gt.iter().map(|p| [p[0] + d, p[1], p[2]]).collect();
    (pred, gt)
}

fn write(dir: &Path, name: &str, vertices: Vec<[f32; 3]>, n: usize) -> PathBuf {
    let path = dir.join(name);
    let clip = Clip::new(
        name,
        vertices,
        FRAMES,
        n,
        vec![[0, 1, 2]],
        "a test clip",
        path.display().to_string(),
    )
    .expect("valid test clip");
    write_clip(&path, &clip).expect("write test clip");
    path
}

/// A prediction of `pred_n` vertices shifted by (d, 0, 0) and a ground truth of `gt_n` vertices (see [`clips`]),
/// written as `pred.bin` and `gt.bin` in a fresh temporary folder.
struct Pair {
    dir: tempfile::TempDir,
    pred: PathBuf,
    gt: PathBuf,
}

fn pair(pred_n: usize, gt_n: usize, d: f32) -> Pair {
    let dir = tempfile::tempdir().unwrap();
    let (pred, _) = clips(pred_n, d);
    let (_, gt) = clips(gt_n, d);
    Pair {
        pred: write(dir.path(), "pred.bin", pred, pred_n),
        gt: write(dir.path(), "gt.bin", gt, gt_n),
        dir,
    }
}

/// `any4d eval metrics PRED GT ARGS…`.
fn eval_metrics(pair: &Pair, args: &[&str]) -> Output {
    let (pred, gt) = (pair.pred.to_str().unwrap(), pair.gt.to_str().unwrap());
    any4d(&[&["eval", "metrics", pred, gt], args].concat())
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn json_reports_raw_values() {
    let out = eval_metrics(&pair(8, 8, 0.3), &["--keyframes", "0,7,15", "--format", "json"]);
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    for key in [
        "rmse",
        "mae_elem",
        "chamfer",
        "dtw",
        "jerk",
        "jerk_gt",
        "accel",
        "energy_ratio",
        "keyframe_rmse",
    ] {
        assert!(json.get(key).is_some(), "missing key {key} in {json}");
    }
    // A shift by (0.3, 0, 0) on every non-keyframe: RMSE = 0.3/√3, mae_elem = 0.3/3, not × 100.
    let rmse = json["rmse"].as_f64().unwrap();
    assert!((rmse - 0.3 / 3f64.sqrt()).abs() < 1e-6, "{rmse}");
    assert!((json["mae_elem"].as_f64().unwrap() - 0.1).abs() < 1e-6);
    // Keyframes were exact copies of ground truth only after replacement: before it they are shifted too.
    assert!((json["keyframe_rmse"].as_f64().unwrap() - rmse).abs() < 1e-6);
}

#[test]
fn table_prints_times_100() {
    let out = eval_metrics(&pair(8, 8, 0.3), &["--keyframes", "0,7,15"]);
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("RMSE ×100"))
        .unwrap_or_else(|| panic!("{stdout}"));
    let value: f64 = line.split_whitespace().last().unwrap().parse().unwrap();
    assert!((value - 30.0 / 3f64.sqrt()).abs() < 1e-3, "{line}");
    assert!(stdout.contains("jerk"), "{stdout}");
}

#[test]
fn mismatched_vertex_counts_fail_with_a_clear_error() {
    let out = eval_metrics(&pair(5, 4, 0.1), &["--format", "json"]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("vertex counts differ: prediction has 5, ground truth has 4"),
        "{stderr}"
    );
    assert!(stderr.contains("pred.bin"), "{stderr}");
}

#[test]
fn bad_keyframes_and_missing_files_fail() {
    let files = pair(4, 4, 0.1);
    let out = eval_metrics(&files, &["--keyframes", "0,16"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("keyframe index 16 is out of range for 16 frames"),
        "{}",
        text(&out.stderr)
    );
    let missing = files.dir.path().join("nope.bin");
    let out = any4d(&["eval", "metrics", missing.to_str().unwrap(), files.gt.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("nope.bin"), "{}", text(&out.stderr));
}

#[test]
fn bench_metrics_runs_on_tiny_clips() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/metrics_reference.py");
    let args = [
        "bench",
        "metrics",
        "--clips",
        "2",
        "--vertices",
        "64",
        "--frames",
        "6",
        "--repeat",
        "1",
    ];
    let out = any4d(&[&args[..], &["--script", script]].concat());
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("ours, 1 thread"), "{stdout}");
    // With numpy and scipy installed the reference runs and must agree; without them the bench says so.
    if stdout.contains("numpy+scipy, 1 core") {
        let line = stdout
            .lines()
            .find(|l| l.starts_with("agreement"))
            .unwrap_or_else(|| panic!("{stdout}"));
        let rel: f64 = line.split_whitespace().nth(8).unwrap().parse().unwrap();
        assert!(rel < 1e-6, "{line}");
    } else {
        assert!(stdout.contains("reference skipped"), "{stdout}");
    }
}

/// A manifest fixes the clips, keyframes and seeds of a run: `--clips`, `--seeds` or `--placement` beside it would be
/// ignored, so they are refused before anything is read.
#[test]
fn eval_run_refuses_item_flags_beside_a_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let (m, out) = (dir.path().join("m.json"), dir.path().join("out"));
    let base = [
        "eval",
        "run",
        "--data",
        "nowhere",
        "--methods",
        "lerp",
        "--manifest",
        m.to_str().unwrap(),
    ];
    for extra in [["--seeds", "42"], ["--clips", "5"], ["--placement", "every_4"]] {
        let o = any4d(&[&base[..], &extra, &["--out", out.to_str().unwrap()]].concat());
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{extra:?} accepted");
        assert!(err.contains(extra[0]) && err.contains("--manifest"), "{extra:?}: {err}");
    }
    assert!(!out.exists(), "nothing written");
}

/// `any4d eval scene` (docs/method.md §6.5): a cube of 8 vertices (frame 0 spans [−1, 1]³, so normalisation is the
/// identity) that sinks 0.5 into a floor slab in its middle frames, scored in JSON; and the errors of a scene file
/// that is not one.
#[test]
fn eval_scene_scores_a_clip_sinking_into_a_floor() {
    let dir = tempfile::tempdir().unwrap();
    let corner = |i: usize| -> [f32; 3] {
        let s = |b: usize| if (i >> b) & 1 == 1 { 1.0 } else { -1.0 };
        [s(0), s(1), s(2)]
    };
    // Frames 0..16; frames 6..=9 lowered by 2.5: the bottom corners (y = −1) reach y = −3.5.
    let vertices: Vec<[f32; 3]> = (0..FRAMES)
        .flat_map(|f| {
            let dy = if (6..=9).contains(&f) { -2.5 } else { 0.0 };
            (0..8).map(corner).map(move |p| [p[0], p[1] + dy, p[2]])
        })
        .collect();
    let clip = write(dir.path(), "cube.bin", vertices, 8);
    // The floor: a slab whose top is at y = −3 (0.5 above the sunk corners), 10 wide.
    let scene = dir.path().join("floor.obj");
    let mut obj = String::new();
    for i in 0..8 {
        let (x, y, z) = (
            if i & 1 == 1 { 5.0 } else { -5.0 },
            if i & 2 == 2 { -3.0 } else { -4.0 },
            if i & 4 == 4 { 5.0 } else { -5.0 },
        );
        obj += &format!("v {x} {y} {z}\n");
    }
    // The outward-wound faces of any4d_data::scene::Scene::cuboid, 1-based.
    for f in [
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
    ] {
        obj += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(&scene, obj).unwrap();
    let (c, sc) = (clip.to_str().unwrap(), scene.to_str().unwrap());
    let out = any4d(&["eval", "scene", c, sc, "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let m: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let close = |k: &str, want: f64| {
        let got = m[k].as_f64().unwrap();
        assert!((got - want).abs() < 1e-5, "{k}: {got} vs {want}");
    };
    close("collision_frames", 4.0 / 16.0);
    close("collision_vertices", 4.0 * 4.0 / (16.0 * 8.0));
    close("max_penetration", 0.5);
    close("foot_skating", 0.0);
    let table = any4d(&["eval", "scene", c, sc]);
    assert!(String::from_utf8_lossy(&table.stdout).contains("max penetration (E9)"));
    // The viewer draws the scene and lists the clip's scene metrics under its panel.
    let page = dir.path().join("page.html");
    let out = any4d(&["view", c, "--scene", sc, "--out", page.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(
        html.contains("\"scene\":{\"faces\"") && html.contains("[\"collision frames\",\"0.250\"]"),
        "{html:.400}"
    );
    std::fs::write(&scene, "v 0 0 0\n").unwrap();
    let bad = any4d(&["eval", "scene", c, sc]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("at least one triangle"));
    let bad = any4d(&["view", c, "--scene", sc, "--out", page.to_str().unwrap()]);
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("reading the scene"));
}

/// A procedural store of small meshes (at most 768 vertices, P = 16) at `store`, made by `data synth` with `args`.
fn synth_store(store: &Path, args: &[&str]) {
    let out = store.to_str().unwrap();
    let mut all = vec!["data", "synth", "--max-vertices", "768", "--p", "16", "--out", out];
    all.extend_from_slice(args);
    let synth = any4d(&all);
    assert!(synth.status.success(), "{}", text(&synth.stderr));
}

/// P-Table 2 by default feeds every row its own generated overlap frame, and its summary says which reference stage
/// 2 had; the ground-truth variant is asked for and labelled.
#[test]
fn table2_defaults_to_each_rows_generated_overlap_and_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("store");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    synth_store(
        &store,
        &[
            "--clips", "6", "--seed", "3", "--frames", "31", "--window", "16", "--stride", "15",
        ],
    );
    for (extra, want) in [
        (None, "each row's own generated overlap frame"),
        (Some("gt"), "the ground-truth overlap frame where it is a keyframe"),
    ] {
        let out = dir.path().join(format!("t2-{}", extra.unwrap_or("default")));
        let mut args = vec![
            "eval".to_string(),
            "run".into(),
            "--protocol".into(),
            "table2".into(),
            "--data".into(),
            s(&store),
            "--split".into(),
            "all".into(),
            "--clips".into(),
            "2".into(),
            "--methods".into(),
            "lerp".into(),
            "--export".into(),
            "0".into(),
            "--no-progress".into(),
            "--out".into(),
            s(&out),
        ];
        if let Some(e) = extra {
            args.extend(["--overlap-source".to_string(), e.to_string()]);
        }
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = any4d(&refs);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
        assert!(md.contains(want), "{extra:?}: {md}");
    }
}

#[test]
fn table5_per_vertex_writes_one_row_per_vertex_and_only_for_table5() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("store");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    synth_store(&store, &["--clips", "3", "--seed", "5"]);
    let vae = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/small/vae");
    let run = |protocol: &str, out: &Path| {
        any4d(&[
            "eval",
            "run",
            "--protocol",
            protocol,
            "--data",
            &s(&store),
            "--split",
            "all",
            "--clips",
            "2",
            "--vae",
            &s(&vae),
            "--methods",
            "lerp",
            "--per-vertex",
            "--no-progress",
            "--out",
            &s(out),
        ])
    };
    let out = dir.path().join("t5");
    let o = run("table5", &out);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let df = ParquetReader::new(std::fs::File::open(out.join("vertices.parquet")).unwrap())
        .finish()
        .unwrap();
    let records = any4d_eval::tables::summary::read_clip_parquet(&out.join("clips.parquet")).unwrap();
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    let opened = any4d_data::store::Store::open(&store).unwrap();
    let vertices: usize = manifest["clips"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            opened
                .get(c["clip"]["index"].as_u64().unwrap() as usize)
                .unwrap()
                .clip
                .n_vertices
        })
        .sum();
    assert_eq!(records.len(), 2);
    assert_eq!(df.height(), vertices, "one row per vertex of each reconstructed window");
    assert_eq!(
        df.column("token_distance").unwrap().null_count(),
        0,
        "the VAE names its tokens"
    );
    let rmse: Vec<f32> = df.column("rmse").unwrap().f32().unwrap().into_no_null_iter().collect();
    // The per-vertex errors square-average to each window's RMSE (E4) (equal vertex counts per frame).
    let mean_sq = |item: u32| {
        let items = df.column("item").unwrap().u32().unwrap();
        let sq: Vec<f64> = items
            .into_no_null_iter()
            .zip(&rmse)
            .filter(|(i, _)| *i == item)
            .map(|(_, r)| f64::from(*r).powi(2))
            .collect();
        (sq.iter().sum::<f64>() / sq.len() as f64).sqrt()
    };
    for r in &records {
        let want = r.metrics["rmse"];
        assert!(
            (mean_sq(r.item as u32) - want).abs() < 1e-4 * want.max(1.0),
            "item {}: {want}",
            r.item
        );
    }
    let o = run("table1", &dir.path().join("t1"));
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("--per-vertex: table 5 only"),
        "{}",
        text(&o.stderr)
    );
}
