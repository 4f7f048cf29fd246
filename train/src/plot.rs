//! Loss-curve PNG of a run: every `metrics.csv` loss column (diagnostics such as the RF's
//! keyframe fraction left out, and the total when it equals the single term) and the validation loss against the step,
//! on a log₁₀ y axis, drawn with the evaluation crate's plotter (`any4d_eval::plot`, no system fonts).

use std::path::Path;

use any4d_eval::plot::{Series, line_plot_fit_y};

use crate::error::Result;
use crate::run_folder::{METRIC_TAIL, read_table};

/// Points (step, log₁₀ value); non-positive and non-finite values cannot sit on a log axis and are skipped.
fn log_points(points: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .filter(|(_, v)| v.is_finite() && *v > 0.0)
        .map(|(s, v)| (s, v.log10()))
        .collect()
}

/// Reads `metrics.csv` (and `valid.csv` when it has rows) and writes the plot to `out` (atomically); the term
/// columns named in `diagnostics` are not losses and are not drawn.
pub fn plot_run(metrics: &Path, valid: &Path, out: &Path, diagnostics: &[String]) -> Result<()> {
    let series = loss_series(metrics, valid, diagnostics)?;
    if series.is_empty() {
        return Ok(());
    }
    Ok(line_plot_fit_y("LOSS CURVES", "STEP", "LOG10 LOSS", &series, out)?)
}

/// The curves of [`plot_run`]: each loss column, then `valid`; empty curves dropped.
fn loss_series(metrics: &Path, valid: &Path, diagnostics: &[String]) -> Result<Vec<Series>> {
    let table = read_table(metrics)?;
    let n_loss_cols = table.header.len().saturating_sub(1 + METRIC_TAIL.len() - 1);
    let mut series = Vec::new();
    let names = &table.header[1..=n_loss_cols];
    // With a single loss term the total equals it: draw the term only.
    let single_term = names
        .iter()
        .filter(|n| *n != "loss" && !diagnostics.contains(n))
        .count()
        == 1;
    for col in 0..n_loss_cols {
        let name = names[col].as_str();
        if diagnostics.iter().any(|d| d == name) || (single_term && name == "loss") {
            continue;
        }
        series.push(Series {
            label: table.header[col + 1].clone(),
            points: log_points(table.rows.iter().map(|(s, v)| (*s as f64, v[col]))),
            errors: None,
        });
    }
    if valid.exists() {
        let v = read_table(valid)?;
        series.push(Series {
            label: "valid".into(),
            points: log_points(
                v.rows
                    .iter()
                    .map(|(s, vals)| (*s as f64, *vals.last().unwrap_or(&f64::NAN))),
            ),
            errors: None,
        });
    }
    series.retain(|s| !s.points.is_empty());
    Ok(series)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run_folder::{METRICS_FILE, RunFolder, VALID_FILE};

    #[test]
    fn rf_curves_leave_the_keyframe_fraction_out() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunFolder::create(dir.path(), "rf", "", &crate::rf_loop::RF_TERMS).unwrap();
        for step in 1..=3 {
            // rf, kf_frac, loss, then lr, grad-norm, steps/s, samples/s.
            run.append_metrics(step, &[0.5, 0.25, 0.5, 1e-4, 1.0, 2.0, 8.0])
                .unwrap();
        }
        let diagnostics = [crate::rf_loop::KF_FRAC_TERM.to_owned()];
        let labels: Vec<String> = loss_series(&run.path(METRICS_FILE), &run.path(VALID_FILE), &diagnostics)
            .unwrap()
            .into_iter()
            .map(|s| s.label)
            .collect();
        assert_eq!(
            labels,
            ["rf"],
            "the total equals the single term and kf_frac is no loss"
        );
        let out = dir.path().join("loss.png");
        plot_run(&run.path(METRICS_FILE), &run.path(VALID_FILE), &out, &diagnostics).unwrap();
        assert!(out.is_file());
    }
}
