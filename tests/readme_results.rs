//! The README's results table is generated from the committed result files of the experiments it cites, so a
//! figure on the front page cannot drift from its source: this test rebuilds the table from those CSVs and fails
//! when the README's copy differs; `ANY4D_BLESS=1 cargo test --test readme_results` writes the rebuilt table into
//! the README instead.

use std::path::Path;

const BEGIN: &str = "<!-- results: generated from the CSVs each row links by tests/readme_results.rs -->";
const END: &str = "<!-- results end -->";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[path = "common/csv.rs"]
mod csv;
use csv::Csv;

/// `a / b / c / d` with `digits` decimals.
fn per_kx(values: impl Iterator<Item = f64>, digits: usize) -> String {
    values.map(|v| format!("{v:.digits$}")).collect::<Vec<_>>().join(" / ")
}

/// The table, one row per claim: what is compared, the figure, and the experiment whose files hold it.
fn table() -> String {
    const FAMILY: &str = "experiments/2026-12-05-vae2000-family";
    const ARMS: &str = "experiments/2026-12-06-corpus-arms";
    let procedural = Csv::read(&format!("{FAMILY}/g64-targets.csv"));
    let heldout = Csv::read(&format!("{FAMILY}/heldout/vs-lerp-baseline-before.csv"));
    let arms = Csv::read(&format!("{ARMS}/results.csv"));
    let cpu = Csv::read("experiments/2026-12-05-cpu-profile/summary.csv");
    let fps = Csv::read("experiments/2026-12-04-fps-lanes/summary.csv");
    let metrics = Csv::read("experiments/2026-12-04-chamfer-grid/summary.csv");
    let kx = ["0", "1", "2", "3"];
    let ratio = |csv: &Csv, row: &str| {
        per_kx(
            kx.iter()
                .map(|k| csv.get(&[("k_extra", k), ("row", row)], "rmse_over_lerp")),
            2,
        )
    };
    let over_baseline = per_kx(
        kx.iter().map(|k| {
            procedural.get(&[("k_extra", k), ("row", "ours")], "rmse_x100")
                / procedural.get(&[("k_extra", k), ("row", "baseline")], "rmse_x100")
        }),
        2,
    );
    let vae = |arm: &str, set: &str, column: &str| arms.get(&[("arm", arm), ("set", set)], column);
    let torch = |network: &str| cpu.get(&[("network", network), ("threads", "1")], "ratio_median");
    let rows = [
        (
            "shipped RF (ours) ÷ lerp, RMSE, procedural validation clips (100 × 3 seeds), K_x 0 / 1 / 2 / 3"
                .to_string(),
            format!("**{}**", ratio(&procedural, "ours")),
            FAMILY,
        ),
        (
            "shipped RF ÷ the paper's Baseline (keyframe replacement), same clips".into(),
            over_baseline,
            FAMILY,
        ),
        (
            "shipped RF ÷ lerp on held-out real game characters (63 windows of 6 objects × 3 seeds)".into(),
            format!("**{}** (worse than lerp)", ratio(&heldout, "ours")),
            FAMILY,
        ),
        (
            "frame-wise VAE reconstruction, table 5 RMSE ×100: shipped, procedural / held-out real".into(),
            format!(
                "{:.2} / {:.2}",
                vae("vae-sr", "procedural-val", "rmse_x100_shipped"),
                vae("vae-sr", "heldout", "rmse_x100_shipped")
            ),
            ARMS,
        ),
        (
            "the same VAE preset on procedural + rigged + real clips, augmented (not shipped)".into(),
            format!(
                "{:.2} / **{:.2}**",
                vae("vae-srra", "procedural-val", "rmse_x100_arm"),
                vae("vae-srra", "heldout", "rmse_x100_arm")
            ),
            ARMS,
        ),
        (
            "paper-size networks, time ÷ AnimateAnyMesh's PyTorch, 1 thread: RF step / frame-wise VAE".into(),
            format!(
                "{:.2} / {:.2}",
                torch("RF forward+backward"),
                torch("frame-wise VAE encode+decode")
            ),
            "experiments/2026-12-05-cpu-profile",
        ),
        (
            "read + normalise + FPS vs numpy, 1 thread (times faster)".into(),
            format!("{:.1}×", fps.get(&[("binary", "after")], "ratio_median")),
            "experiments/2026-12-04-fps-lanes",
        ),
        (
            "metrics (E1)–(E7) vs numpy + scipy, 1 / 2 threads (times faster)".into(),
            format!(
                "{:.1}× / {:.1}×",
                metrics.get(&[("binary", "after")], "speedup_1_thread_median"),
                metrics.get(&[("binary", "after")], "speedup_2_threads_median")
            ),
            "experiments/2026-12-04-chamfer-grid",
        ),
    ];
    let mut out = String::from("| claim | measured | source |\n|---|---|---|\n");
    for (claim, figure, source) in rows {
        let name = source.rsplit('/').next().unwrap_or(source);
        out.push_str(&format!("| {claim} | {figure} | [{name}]({source}/README.md) |\n"));
    }
    out
}

#[test]
fn the_readme_results_table_is_generated_from_committed_csvs() {
    let path = root().join("README.md");
    let readme = std::fs::read_to_string(&path).unwrap();
    let start = readme.find(BEGIN).expect("README.md has no results marker") + BEGIN.len() + 1;
    let end = readme[start..].find(END).expect("README.md has no results end marker") + start;
    let fresh = table();
    if std::env::var_os("ANY4D_BLESS").is_some() {
        std::fs::write(&path, format!("{}{fresh}{}", &readme[..start], &readme[end..])).unwrap();
        return;
    }
    assert_eq!(
        &readme[start..end],
        fresh,
        "README.md's results table differs from its CSVs; `ANY4D_BLESS=1 cargo test --test readme_results` rewrites it"
    );
}

#[test]
fn a_csv_row_is_found_by_its_key_and_only_one() {
    let csv = Csv {
        path: "x.csv".into(),
        header: vec!["k".into(), "row".into(), "v".into()],
        rows: vec![
            vec!["0".into(), "a".into(), "1.5".into()],
            vec!["0".into(), "b".into(), "2".into()],
        ],
    };
    assert_eq!(csv.get(&[("k", "0"), ("row", "b")], "v"), 2.0);
    let twice = std::panic::catch_unwind(|| csv.get(&[("k", "0")], "v"));
    assert!(twice.is_err(), "two matching rows must not pick one silently");
    assert_eq!(per_kx([0.6666, 1.0].into_iter(), 2), "0.67 / 1.00");
}
