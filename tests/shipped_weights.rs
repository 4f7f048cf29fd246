//! The shipped small models (`weights/small/{vae,rf,baseline-rf}`) load as they are through `any4d eval run
//! --vae/--rf/--baseline-rf` and reproduce the metrics committed in `weights/small/check/summary.csv` on the same
//! few procedural clips (`weights/small/PROVENANCE.md` gives the commands that wrote it).
//!
//! Tolerance: 2 % relative (plus 1e-3 absolute on the ×100 scale) per value. The RFs are stored in f16 and run in
//! f32 (loading casts them back), as they did when the committed table was written, and the
//! sampler integrates 16 steps, so a machine whose matrix kernels sum in another order (AVX2 instead of AVX-512)
//! moves the last digits; a wrong checkpoint, a wrong latent statistic or a changed sampler moves them by far more.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod common;
use common::{any4d, text};

/// `data synth` arguments of the check store and `eval run` arguments of the check table, as in PROVENANCE.md.
const SYNTH: &[&str] = &["--clips", "12", "--seed", "2026", "--max-vertices", "768", "--p", "128"];
const EVAL: &[&str] = &[
    "--protocol",
    "table1",
    "--split",
    "all",
    "--clips",
    "3",
    "--n-grid",
    "16",
    "--methods",
    "keyframe_rf,replacement_rf,lerp",
    "--export",
    "0",
    "--no-progress",
];
const COLUMNS: &[&str] = &["rmse_mean", "chamfer_mean", "dtw_mean", "jerk_ratio_mean"];

fn weights() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/small")
}

/// (method, k_extra) → the checked columns of a table-1 `summary.csv`.
fn read_summary(path: &Path) -> BTreeMap<(String, String), Vec<f64>> {
    let body = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = body.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    };
    let (method, k) = (col("method"), col("k_extra"));
    let wanted: Vec<usize> = COLUMNS.iter().map(|c| col(c)).collect();
    lines
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            let values = wanted.iter().map(|&i| f[i].parse::<f64>().expect(f[i])).collect();
            ((f[method].to_string(), f[k].to_string()), values)
        })
        .collect()
}

#[test]
fn shipped_small_models_load_and_reproduce_their_committed_metrics() {
    let w = weights();
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("store");
    let store_s = store.to_str().unwrap();
    let mut synth = vec!["data", "synth", "--out", store_s];
    synth.extend_from_slice(SYNTH);
    let out = any4d(&synth);
    assert!(out.status.success(), "{:?}", text(&out));

    let table = dir.path().join("table");
    let (rf, base, vae) = (w.join("rf"), w.join("baseline-rf"), w.join("vae"));
    let mut args = vec!["eval", "run", "--data", store_s, "--out", table.to_str().unwrap()];
    args.extend_from_slice(EVAL);
    args.extend_from_slice(&[
        "--rf",
        rf.to_str().unwrap(),
        "--baseline-rf",
        base.to_str().unwrap(),
        "--vae",
        vae.to_str().unwrap(),
    ]);
    let out = any4d(&args);
    assert!(out.status.success(), "{:?}", text(&out));

    // Run from the repository root (as the tests are), the summary names the runs as a clone has them.
    let md = std::fs::read_to_string(table.join("summary.md")).unwrap();
    assert!(md.contains("checkpoint weights/small/rf (step "), "{md}");
    let got = read_summary(&table.join("summary.csv"));
    let want = read_summary(&w.join("check/summary.csv"));
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>(),
        "the same rows"
    );
    for (key, expect) in &want {
        for ((g, e), name) in got[key].iter().zip(expect).zip(COLUMNS) {
            assert!(
                (g - e).abs() <= 0.02 * e.abs() + 1e-3,
                "{key:?} {name}: measured {g}, committed {e}"
            );
        }
    }
}
