//! P-Table 2 (docs/method.md §7): 31-frame sequences completed by the two-stage rollout (H1)–(H4) with keyframes 0,
//! 15, 30, scored by (E1)–(E3) over the non-keyframes and the seam jerk around frame 15.

use std::collections::BTreeMap;

use any4d_data::Clip;

use super::summary::{Layout, MetricColumn, col, pooled};
use super::{Items, TableOptions, TableReport, run_completion};
use crate::methods::{Method, metrics_map};
use crate::metrics::{Motion, evaluate_clip, replace_keyframes};
use crate::protocol::ManifestOptions;
use crate::rollout::{OverlapSource, Rollout, RolloutSpec, rollout, seam_jerk};

use crate::error::{EvalError, Result};

/// Title and columns of P-Table 2.
pub const LAYOUT: Layout = Layout {
    title: "Table 2: long-horizon completion (31 frames, two-stage rollout, keyframes 0/15/30)",
    columns: COLUMNS,
    k_column: false,
};

const COLUMNS: &[MetricColumn] = &[
    col("rmse", "RMSE ×100", 100.0),
    col("chamfer", "Chamfer ×100", 100.0),
    col("dtw", "DTW ×100", 100.0),
    col("jerk_ratio", "jerk / GT", 1.0),
    pooled("jerk_pooled", "jerk", "jerk_gt", "jerk Σ/ΣGT"),
    col("seam_jerk_ratio", "seam jerk / GT", 1.0),
    pooled("seam_jerk_pooled", "seam_jerk", "seam_jerk_gt", "seam jerk Σ/ΣGT"),
];

/// Frames on each side of a seam whose jerk is reported (docs/method.md §7: a ±2-frame band).
pub const SEAM_HALF_WIDTH: usize = 2;

/// The options of P-Table 2.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LongHorizon {
    /// Which items (pairs of windows sharing a frame).
    pub items: Items,
    /// Reference of stage 2 (docs/method.md §7, §8 A8): `eval run` defaults to each row's generated frame.
    pub overlap_source: OverlapSource,
}

impl LongHorizon {
    /// Runs the table.
    pub fn run(&self, opts: &TableOptions) -> Result<TableReport> {
        let draw = ManifestOptions::table2(opts.data.display().to_string());
        run_completion(opts, &LAYOUT, &self.items, draw, Some(self.overlap_source), false)
    }
}

/// A prediction and its metrics by name.
pub(crate) type Scored = (Vec<[f32; 3]>, BTreeMap<String, f64>);

/// One long-horizon generation (docs/method.md §7) scored by (E1)–(E7) over 𝒰 = {0..30} \ {0, 15, 30} plus the seam
/// jerk.
pub(crate) fn long_horizon(
    method: &dyn Method,
    gt: &Clip,
    keyframes: &[usize],
    captions: &[String],
    seed: u64,
    overlap_source: OverlapSource,
) -> Result<Scored> {
    let n = gt.n_vertices;
    let label = method.kind().label();
    let r = generate_long(method, gt, keyframes, captions, seed, overlap_source)?;
    let err = |e: crate::metrics::EvalError| EvalError::invalid(&gt.id, &label, e.to_string());
    let pred = Motion::new(&r.vertices, gt.frames, n).map_err(err)?;
    let truth = Motion::from_clip(gt).map_err(err)?;
    let mut metrics = metrics_map(&evaluate_clip(pred, truth, keyframes).map_err(err)?);
    let assembled = replace_keyframes(pred, truth, keyframes).map_err(err)?;
    let (mut sum_p, mut sum_g, mut seams) = (0.0, 0.0, 0usize);
    for &s in &r.starts[1..] {
        if let (Some(p), Some(g)) = (
            seam_jerk(&assembled, n, s, SEAM_HALF_WIDTH, 1.0),
            seam_jerk(&gt.vertices, n, s, SEAM_HALF_WIDTH, 1.0),
        ) {
            sum_p += p;
            sum_g += g;
            seams += 1;
        }
    }
    let seams = seams.max(1) as f64;
    metrics.insert("seam_jerk".into(), sum_p / seams);
    metrics.insert("seam_jerk_gt".into(), sum_g / seams);
    metrics.insert("seam_jerk_ratio".into(), sum_p / sum_g);
    Ok((r.vertices, metrics))
}

/// The two-stage generation alone (docs/method.md §7): each window completed by `method` and assembled with its own
/// keyframes, stitched in the global frame. What P-Table 4 times (no scoring).
pub(crate) fn generate_long(
    method: &dyn Method,
    gt: &Clip,
    keyframes: &[usize],
    captions: &[String],
    seed: u64,
    overlap_source: OverlapSource,
) -> Result<Rollout> {
    let spec = RolloutSpec {
        overlap_source,
        ..RolloutSpec::paper()
    };
    generate_windows(method, gt, keyframes, captions, seed, spec)
}

/// Completes a sequence of any length ≥ `spec.window` from its keyframes (docs/method.md §7): windows laid out by
/// `spec`, each completed by `method` with seed `seed + window index` and assembled with its own keyframes, stitched
/// in the global frame. `gt` is in the normalised frame of its frame 0; only its frame 0 and its keyframes are read
/// (plus, with a ground-truth overlap, the keyframes a window starts on). A sequence of exactly one window is one
/// completion.
pub fn generate_windows(
    method: &dyn Method,
    gt: &Clip,
    keyframes: &[usize],
    captions: &[String],
    seed: u64,
    spec: RolloutSpec,
) -> Result<Rollout> {
    let prompts: Vec<&str> = captions.iter().map(String::as_str).collect();
    let n = gt.n_vertices;
    rollout(&gt.vertices, n, keyframes, &prompts, spec, |w| {
        let window = Clip::new(
            &gt.id,
            w.vertices.clone(),
            spec.window,
            n,
            gt.faces.clone(),
            w.caption,
            &gt.source,
        )?;
        let mut pred = method.complete(&window, &w.keyframes, w.caption, seed.wrapping_add(w.index as u64))?;
        // The window's assembly (docs/method.md §4.6, §7 step 2): its keyframes are the meshes it was given, so the
        // overlap frame a later window starts from is the keyframe itself.
        for &k in w.keyframes.iter().filter(|&&k| k < spec.window) {
            pred[k * n..(k + 1) * n].copy_from_slice(&w.vertices[k * n..(k + 1) * n]);
        }
        Ok(pred)
    })
}
