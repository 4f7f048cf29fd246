//! P-Table 1 (docs/method.md §6.1): short-horizon completion of 16-frame windows from first + last + K_x = 0..3
//! keyframes (or another placement, §8 X4), RMSE / Chamfer / DTW × 100 per method and K_x.

use crate::error::EvalError;
use any4d_data::keyframes::Placement;

use super::summary::{Layout, MetricColumn, col, pooled, pooled_scaled};
use super::{Items, TableOptions, TableReport, run_completion};
use crate::protocol::ManifestOptions;

/// Title and columns of P-Table 1.
pub const LAYOUT: Layout = Layout {
    title: "Table 1: short-horizon completion (16 frames, K_x extra keyframes)",
    columns: COLUMNS,
    k_column: true,
};

const COLUMNS: &[MetricColumn] = &BASE;

const BASE: [MetricColumn; 7] = [
    col("rmse", "RMSE ×100", 100.0),
    col("chamfer", "Chamfer ×100", 100.0),
    col("dtw", "DTW ×100", 100.0),
    col("mae_elem", "MAE ×100", 100.0),
    col("jerk_ratio", "jerk / GT", 1.0),
    pooled("jerk_pooled", "jerk", "jerk_gt", "jerk Σ/ΣGT"),
    col("energy_ratio", "motion / GT", 1.0),
];

/// P-Table 1 of a store with scenes: the same columns, then the scene metrics (E8)–(E10) of docs/method.md §6.5
/// averaged over the clips that have a scene (× 100: percentages, and the penetration in hundredths of the
/// normalised half-extent).
pub const LAYOUT_SCENES: Layout = Layout {
    title: "Table 1: short-horizon completion in scenes (16 frames, K_x extra keyframes)",
    columns: COLUMNS_SCENES,
    k_column: true,
};

const COLUMNS_SCENES: &[MetricColumn] = &with_scene_columns();

const SCENE: [MetricColumn; 4] = [
    pooled_scaled(
        "scene_collision_frames",
        "collision_frames",
        "in_scene",
        "collision frames %",
        100.0,
    ),
    pooled_scaled(
        "scene_collision_vertices",
        "collision_vertices",
        "in_scene",
        "collision vertices %",
        100.0,
    ),
    pooled_scaled(
        "scene_max_penetration",
        "max_penetration",
        "in_scene",
        "max penetration ×100",
        100.0,
    ),
    pooled_scaled(
        "scene_foot_skating",
        "foot_skating",
        "in_scene",
        "foot skating %",
        100.0,
    ),
];

/// [`BASE`] then [`SCENE`].
const fn with_scene_columns() -> [MetricColumn; 11] {
    let mut out = [SCENE[0]; 11];
    let mut i = 0;
    while i < BASE.len() {
        out[i] = BASE[i];
        i += 1;
    }
    while i < out.len() {
        out[i] = SCENE[i - BASE.len()];
        i += 1;
    }
    out
}

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
    pub fn run(&self, opts: &TableOptions) -> Result<TableReport, EvalError> {
        let draw = ManifestOptions {
            placement: self.placement,
            ..ManifestOptions::table1(opts.data.display().to_string())
        };
        let scenes = any4d_data::store::Store::open(&opts.data)?.has_scenes();
        let layout = if scenes { &LAYOUT_SCENES } else { &LAYOUT };
        run_completion(opts, layout, &self.items, draw, None, true)
    }
}

/// The scene metrics of a prediction for the records of a store with scenes (docs/method.md §6.5, (E8)–(E10), in
/// the window's normalised frame): `in_scene` 1 and the four metrics for an item with a scene; every key NaN for an
/// item without one, so that every record of the table carries the same names and the pooled columns
/// ([`LAYOUT_SCENES`]) average over the items that have a scene.
pub(crate) fn scene_columns(
    scene: Option<&any4d_data::scene::Scene>,
    prediction: &[[f32; 3]],
    gt: &any4d_data::Clip,
) -> Result<std::collections::BTreeMap<String, f64>, EvalError> {
    use crate::scene_metrics::{ContactThresholds, scene_metrics};
    let values = match scene {
        Some(scene) => {
            let motion = crate::metrics::Motion::new(prediction, gt.frames, gt.n_vertices)
                .map_err(|e| EvalError::invalid(&gt.id, "scene metrics", e.to_string()))?;
            let m = scene_metrics(motion, scene, ContactThresholds::default())
                .map_err(|e| EvalError::invalid(&gt.id, "scene metrics", e.to_string()))?;
            [
                1.0,
                m.collision_frames,
                m.collision_vertices,
                m.max_penetration,
                m.foot_skating,
            ]
        }
        None => [f64::NAN; 5],
    };
    let keys = [
        "in_scene",
        "collision_frames",
        "collision_vertices",
        "max_penetration",
        "foot_skating",
    ];
    Ok(keys.iter().map(|k| k.to_string()).zip(values).collect())
}
