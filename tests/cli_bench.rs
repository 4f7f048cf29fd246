//! `any4d bench train` (RF, VAE and BD-LSTM presets), `bench complete` and `bench acap` run as a user would: the built binary, its exit code and its output.

use std::path::{Path, PathBuf};

mod common;
use common::{any4d, text};

fn preset(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn rf_preset_prints_the_header_and_a_positive_rate_without_a_store() {
    let tiny = preset("configs/rf/tiny.toml");
    let out = any4d(&[
        "bench",
        "train",
        "--config",
        p(&tiny),
        "--steps",
        "2",
        "--backends",
        "flex",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("model FLOPs per step:"), "{stdout}");
    let header: Vec<&str> = stdout
        .lines()
        .find(|l| l.starts_with("backend"))
        .unwrap_or_else(|| panic!("no header line in {stdout}"))
        .split_whitespace()
        .collect();
    for column in [
        "micro_batch",
        "median_s",
        "steps/s",
        "samples/s",
        "GFLOP/step",
        "GFLOP/s",
    ] {
        assert!(header.contains(&column), "header {header:?} lacks {column}");
    }
    let row: Vec<&str> = stdout
        .lines()
        .find(|l| l.starts_with("flex"))
        .unwrap_or_else(|| panic!("no flex row in {stdout}"))
        .split_whitespace()
        .collect();
    assert_eq!(row.len(), header.len(), "{row:?} vs {header:?}");
    let value = |name: &str| -> f64 {
        let i = header.iter().position(|h| *h == name).unwrap();
        row[i].parse().unwrap_or_else(|e| panic!("{name} = {:?}: {e}", row[i]))
    };
    assert!(value("steps/s") > 0.0, "{stdout}");
    assert!(value("GFLOP/step") > 0.0, "{stdout}");
    // The preset's micro-batch: samples/s = micro_batch × steps/s (both rounded in the table).
    assert_eq!(value("micro_batch"), 4.0);
    let ratio = value("samples/s") / value("steps/s");
    assert!((ratio - 4.0).abs() < 0.05, "samples/s / steps/s = {ratio}");
}

#[test]
fn broken_configs_and_arguments_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let tiny = std::fs::read_to_string(preset("configs/rf/tiny.toml")).unwrap();
    let fail = |args: &[&str], needles: &[&str]| {
        let out = any4d(args);
        let (stdout, stderr) = text(&out);
        assert!(!out.status.success(), "{args:?} succeeded: {stdout}");
        for needle in needles {
            assert!(stderr.contains(needle), "{args:?}: {needle:?} not in {stderr}");
        }
        assert!(!stderr.contains("panicked"), "{stderr}");
    };

    let bad_width = tmp.path().join("bad_width.toml");
    std::fs::write(&bad_width, tiny.replacen("width = 64", "width = 0", 1)).unwrap();
    fail(
        &["bench", "train", "--config", p(&bad_width), "--steps", "2"],
        &["bad_width.toml", "model.width"],
    );

    let unknown_key = tmp.path().join("unknown_key.toml");
    std::fs::write(&unknown_key, tiny.replacen("[rf]\n", "[rf]\nspeed = 3\n", 1)).unwrap();
    fail(
        &["bench", "train", "--config", p(&unknown_key), "--steps", "2"],
        &["unknown_key.toml", "speed"],
    );

    let neither = tmp.path().join("neither.toml");
    std::fs::write(&neither, "[model]\nwidth = 8\n").unwrap();
    fail(
        &["bench", "train", "--config", p(&neither), "--steps", "2"],
        &["neither.toml", "neither an RF run config"],
    );

    let not_toml = tmp.path().join("not_toml.toml");
    std::fs::write(&not_toml, "[rf\n").unwrap();
    fail(
        &["bench", "train", "--config", p(&not_toml)],
        &["not_toml.toml", "invalid TOML"],
    );

    let missing = tmp.path().join("missing.toml");
    fail(
        &["bench", "train", "--config", p(&missing)],
        &["missing.toml", "cannot read"],
    );

    let rf = preset("configs/rf/tiny.toml");
    fail(
        &["bench", "train", "--config", p(&rf), "--steps", "1"],
        &["--steps must be at least 2"],
    );
    let vae = preset("configs/vae/tiny.toml");
    fail(
        &["bench", "train", "--config", p(&vae), "--steps", "2"],
        &["--data STORE"],
    );
    let (latent, acap) = (
        preset("configs/bdlstm/tiny.toml"),
        preset("configs/bdlstm/acap_tiny.toml"),
    );
    let store = tmp.path().join("no-store");
    fail(
        &["bench", "train", "--config", p(&latent), "--steps", "2"],
        &["--data STORE"],
    );
    fail(
        &[
            "bench",
            "train",
            "--config",
            p(&latent),
            "--data",
            p(&store),
            "--steps",
            "2",
        ],
        &["--vae RUN"],
    );
    fail(
        &[
            "bench",
            "train",
            "--config",
            p(&acap),
            "--data",
            p(&store),
            "--vae",
            p(&store),
        ],
        &["drop --vae"],
    );
    fail(
        &["bench", "train", "--config", p(&rf), "--vae", p(&store)],
        &["--vae applies to latent BD-LSTM presets only"],
    );
}

/// The ACAP BD-LSTM preset trains on a single-topology store for a few steps and prints one row per backend.
#[test]
fn acap_bdlstm_preset_prints_a_positive_training_rate() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let mut synth = vec!["data", "synth", "--out", p(&store)];
    synth.extend("--clips 6 --seed 3 --body blob --min-vertices 256 --max-vertices 512 --p 64".split(' '));
    let out = any4d(&synth);
    assert!(out.status.success(), "{:?}", text(&out));
    let acap = preset("configs/bdlstm/acap_tiny.toml");
    let mut args = vec!["bench", "train", "--config", p(&acap), "--data", p(&store)];
    args.extend(["--steps", "3", "--backends", "flex"]);
    let out = any4d(&args);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let row = stdout.lines().find(|l| l.starts_with("flex")).expect(&stdout);
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cols[1], "3", "{row}");
    let rate: f64 = cols[2].parse().expect(row);
    assert!(rate.is_finite() && rate > 0.0, "{row}");
}

/// Also the documented vertex policy: 2,000 vertices, twice the small model's training maximum, complete (the
/// decoder queries every vertex; only fewer than P are refused).
#[test]
fn complete_benchmark_prints_one_row_per_vertex_count() {
    let rf = preset("weights/small/rf");
    let out = any4d(&[
        "bench",
        "complete",
        "--rf",
        p(&rf),
        "--vertices",
        "300,2000",
        "--reps",
        "1",
        "--steps",
        "2",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("| 300 |") && stdout.contains("| 2000 |"), "{stdout}");
    let out = any4d(&["bench", "complete", "--rf", p(&rf), "--reps", "0"]);
    assert!(!out.status.success() && text(&out).1.contains("--reps"));
}

/// `scripts/gpu_check.sh --dry-run` runs the GPU check's whole sequence on the CPU at tiny sizes: every f32 check gets
/// a numeric row in one CSV (networks, training throughput and peak fraction, P-Table 4 per size, the small preset),
/// so the script is ready for the one short call a lent GPU allows. The bf16 steps (cuda's half precision) reach the
/// CPU backend, which refuses them only after their command lines parsed: their rows read "failed", the rest still
/// run, and the exit status says a step failed. `bench sample` refuses configs that do not fit.
#[test]
fn the_gpu_check_script_runs_dry_on_the_cpu_and_writes_one_numeric_row_per_check() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("check");
    let status = std::process::Command::new("bash")
        .arg(preset("scripts/gpu_check.sh"))
        .arg("--dry-run")
        .arg(&out)
        .env("ANY4D_BIN", env!("CARGO_BIN_EXE_any4d"))
        .env("ANY4D_GPU_HALF", "bf16")
        .output()
        .expect("bash runs the script");
    let (stdout, stderr) = text(&status);
    assert_eq!(status.status.code(), Some(1), "{stdout}\n{stderr}");
    let csv = std::fs::read_to_string(out.join("gpu_check.csv")).unwrap();
    let mut checks = Vec::new();
    for line in csv.lines().skip(1) {
        let fields: Vec<&str> = line.splitn(6, ',').collect();
        assert_eq!(fields.len(), 6, "{line}");
        if fields[2] == "bf16" {
            assert_eq!(fields[3], "failed", "{line}");
        } else if fields[0] != "device" {
            let value = fields[3].trim_end_matches('%');
            assert!(value.parse::<f64>().is_ok_and(|v| v >= 0.0), "not a number: {line}");
        }
        checks.push(fields[0].to_string());
    }
    for want in [
        "model: RF forward+backward",
        "model: frame-wise VAE encode+decode",
        "train_paper: steps/s",
        "train_paper: fraction of peak",
        "table4: 16 frames 512 vertices",
        "table4: 31 frames 256 vertices",
        "train_small: steps/s",
    ] {
        assert!(checks.iter().any(|c| c == want), "no `{want}` row in\n{csv}");
    }
    for (step, row) in [
        ("bench_model_bf16", "model: networks"),
        ("train_paper_bf16", "train_paper_bf16"),
    ] {
        assert!(checks.iter().any(|c| c == row), "no `{row}` row in\n{csv}");
        let log = std::fs::read_to_string(out.join(format!("{step}.log"))).unwrap();
        assert!(
            log.contains("precision `bf16` refused on backend `flex`"),
            "{step}: {log}"
        );
    }

    let vae = preset("configs/vae/dymesh_tiny.toml");
    let bad = any4d(&[
        "bench",
        "sample",
        "--vae-config",
        p(&vae),
        "--rf-config",
        p(&preset("configs/rf/tiny.toml")),
        "--out",
        p(&dir.path().join("t4")),
    ]);
    let (stdout, stderr) = text(&bad);
    assert!(!bad.status.success());
    assert!(stderr.contains("frame-wise"), "{stdout}\n{stderr}");
}

#[test]
fn acap_benchmark_prints_our_rows_and_refuses_bad_sizes() {
    // A missing interpreter skips the reference and says so; our rows still print.
    let out = any4d(&[
        "bench",
        "acap",
        "--vertices",
        "512",
        "--frames",
        "4",
        "--repeat",
        "1",
        "--python",
        "/nonexistent/python3",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for row in ["| ours, 1 thread |", "reference skipped"] {
        assert!(stdout.contains(row), "{row} missing from {stdout}");
    }
    let ours = stdout.lines().find(|l| l.starts_with("| ours, 1 thread")).unwrap();
    let total: f64 = ours.split('|').nth(4).unwrap().trim().parse().unwrap();
    assert!(total > 0.0, "{ours}");
    for (flag, value, needle) in [("--vertices", "100", "vertices"), ("--repeat", "0", "--repeat")] {
        let out = any4d(&["bench", "acap", flag, value]);
        let (stdout, stderr) = text(&out);
        assert!(!out.status.success(), "{flag} {value}: {stdout}");
        assert!(stderr.contains(needle), "{flag} {value}: {stderr}");
    }
}

#[test]
fn scene_benchmark_prints_our_rows_and_refuses_empty_sizes() {
    let out = any4d(&[
        "bench",
        "scene",
        "--clips",
        "1",
        "--keyframes",
        "2",
        "--anchors",
        "16",
        "--repeat",
        "1",
        "--python",
        "/nonexistent/python3",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for row in ["| ours, 1 thread |", "reference skipped"] {
        assert!(stdout.contains(row), "{row} missing from {stdout}");
    }
    let ours = stdout.lines().find(|l| l.starts_with("| ours, 1 thread")).unwrap();
    let ms: f64 = ours.split('|').nth(2).unwrap().trim().parse().unwrap();
    assert!(ms > 0.0, "{ours}");
    for flag in ["--clips", "--keyframes", "--anchors", "--repeat"] {
        let out = any4d(&["bench", "scene", flag, "0"]);
        let (stdout, stderr) = text(&out);
        assert!(!out.status.success(), "{flag} 0: {stdout}");
        assert!(stderr.contains(flag), "{flag} 0: {stderr}");
    }
}
