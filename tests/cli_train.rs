//! `any4d train` and `any4d model summary` through the binary: `--set` overrides reach the parsed config and an
//! unknown key is refused, and DDP on CPU devices and f16 training are refused before a run folder exists.

use std::path::PathBuf;

mod common;
use common::{any4d, text};

fn preset(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn set_overrides_change_the_network_and_unknown_keys_fail() {
    let tiny = preset("configs/rf/tiny.toml");
    let tiny = tiny.to_str().unwrap();
    let total = |args: &[&str]| {
        let out = any4d(&[&["model", "summary", "--config", tiny][..], args].concat());
        let (stdout, stderr) = text(&out);
        assert!(out.status.success(), "{args:?}: {stderr}");
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with("total"))
            .unwrap_or_else(|| panic!("{stdout}"));
        line.split_whitespace().nth(1).unwrap().parse::<usize>().unwrap()
    };
    let base = total(&[]);
    let wider = total(&["--set", "model.width=128", "--set", "model.heads=4"]);
    assert!(wider > base, "a wider MMDiT has more parameters: {wider} vs {base}");
    assert!(
        total(&["--set", "model.conditioning=none"]) < base,
        "no mask channels: fewer inputs"
    );

    let out = any4d(&["model", "summary", "--config", tiny, "--set", "model.widht=128"]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("unknown key `model.widht`") && stderr.contains("tiny.toml"),
        "{stderr}"
    );
}

/// `train vae` of the tiny preset with `args` must fail before it creates a run folder, saying `reason`.
fn assert_refused_before_a_run_folder(args: &[&str], reason: &str) {
    let dir = tempfile::tempdir().unwrap();
    let runs = dir.path().join("runs");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_any4d"))
        .args(["train", "vae", "--config"])
        .arg(preset("configs/vae/tiny.toml"))
        .args(["--data", "no-store-needed"])
        .args(args)
        .arg("--runs-dir")
        .arg(&runs)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} started: {stderr}");
    assert!(stderr.contains(reason), "{stderr}");
    assert!(!runs.exists(), "a run folder was created for a run that cannot start");
}

#[test]
fn cli_refuses_ddp_on_cpu_devices_before_creating_a_run_folder() {
    assert_refused_before_a_run_folder(
        &["--devices", "flex,flex", "--strategy", "ddp"],
        "--strategy ddp needs cuda devices",
    );
}

/// f16 is refused for training (it diverges: parameters and optimiser state in f16) before a run folder exists, by
/// `train` and by `bench train`, with the reason.
#[test]
fn cli_refuses_f16_training_before_creating_a_run_folder() {
    assert_refused_before_a_run_folder(&["--set", "device.precision=\"f16\""], "training in f16 diverges");

    let tiny = preset("configs/rf/tiny.toml");
    let out = any4d(&[
        "bench",
        "train",
        "--config",
        tiny.to_str().unwrap(),
        "--backends",
        "flex",
        "--precision",
        "f16",
        "--steps",
        "2",
    ]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success(), "bench train in f16 ran: {stderr}");
    assert!(stderr.contains("training in f16 diverges"), "{stderr}");
}
