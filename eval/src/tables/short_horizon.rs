//! P-Table 1 (docs/method.md §6.1): short-horizon completion of 16-frame windows from first + last + K_x = 0..3
//! keyframes (or another placement, §8 X4), RMSE / Chamfer / DTW × 100 per method and K_x.

use any4d_data::DataError;
use any4d_data::keyframes::Placement;

use super::summary::{Layout, MetricColumn, col, pooled};
use super::{Items, TableOptions, TableReport, run_completion};
use crate::protocol::ManifestOptions;
use crate::rollout::OverlapSource;

/// Title and columns of P-Table 1.
pub const LAYOUT: Layout = Layout {
    title: "Table 1: short-horizon completion (16 frames, K_x extra keyframes)",
    columns: COLUMNS,
    k_column: true,
};

const COLUMNS: &[MetricColumn] = &[
    col("rmse", "RMSE ×100", 100.0),
    col("chamfer", "Chamfer ×100", 100.0),
    col("dtw", "DTW ×100", 100.0),
    col("mae_elem", "MAE ×100", 100.0),
    col("jerk_ratio", "jerk / GT", 1.0),
    pooled("jerk_pooled", "jerk", "jerk_gt", "jerk Σ/ΣGT"),
    col("energy_ratio", "motion / GT", 1.0),
];

/// The options of P-Table 1.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShortHorizon {
    /// Which items.
    pub items: Items,
    /// Keyframe placement ([`Placement::PAPER`] by default; §8 X4).
    pub placement: Placement,
}

impl ShortHorizon {
    /// Runs the table.
    pub fn run(&self, opts: &TableOptions) -> Result<TableReport, DataError> {
        let draw = ManifestOptions {
            placement: self.placement,
            ..ManifestOptions::table1(opts.data.display().to_string())
        };
        run_completion(opts, &LAYOUT, &self.items, draw, OverlapSource::GroundTruth, true)
    }
}
