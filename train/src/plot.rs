//! Loss-curve PNG of a run (issue 5 item 3): every `metrics.csv` loss column and the validation loss against the
//! step, on a log₁₀ y axis, drawn with the evaluation crate's plotter (`any4d_eval::plot`, no system fonts).

use std::path::Path;

use any4d_eval::plot::{Series, line_plot};

use crate::error::{Result, TrainError};
use crate::run_folder::{METRIC_TAIL, read_table};

/// Points (step, log₁₀ value); non-positive and non-finite values cannot sit on a log axis and are skipped.
fn log_points(points: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .filter(|(_, v)| v.is_finite() && *v > 0.0)
        .map(|(s, v)| (s, v.log10()))
        .collect()
}

/// Reads `metrics.csv` (and `valid.csv` when it has rows) and writes the plot to `out` (atomically).
pub fn plot_run(metrics: &Path, valid: &Path, out: &Path) -> Result<()> {
    let table = read_table(metrics)?;
    let n_loss_cols = table.header.len().saturating_sub(1 + METRIC_TAIL.len() - 1);
    let mut series = Vec::new();
    for col in 0..n_loss_cols {
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
    if series.is_empty() {
        return Ok(());
    }
    line_plot("LOSS CURVES", "STEP", "LOG10 LOSS", &series, out).map_err(|e| TrainError::Other(e.to_string()))
}
