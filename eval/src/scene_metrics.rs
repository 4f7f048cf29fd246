//! Scene metrics (docs/method.md §6.5, (E8)–(E10)): how a clip sits in its static scene — how often and how deep it
//! passes into the scene's solid parts, and how much the vertices that touch the ground slide.
//!
//! A point is inside the scene when its generalized winding number, Σ over triangles of the solid angle the triangle
//! subtends (Van Oosterom–Strackee) / 4π, exceeds ½: exactly 1 inside a closed, outward-wound part and 0 outside,
//! robust to small gaps. Its depth is the distance to the nearest triangle (exact point–triangle distance). Both
//! visit every triangle for every vertex: O(T·N·M), with frames in parallel.

use any4d_data::scene::Scene;
pub use any4d_data::scene::geometry::{signed_distance, surface_distance, winding_number};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::metrics::{EvalError, Motion, Result};

/// Distances of (E10): a vertex touches the ground within `contact` of the scene's surface (outside or inside), and
/// skates when it moves more than `slide` along the ground (x–z) between two frames in which it touches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactThresholds {
    pub contact: f64,
    pub slide: f64,
}

impl Default for ContactThresholds {
    /// 2 % and 1 % of the unit half-extent that normalisation (D1)–(D3) gives frame 0.
    fn default() -> Self {
        ContactThresholds {
            contact: 0.02,
            slide: 0.01,
        }
    }
}

/// (E8)–(E10) of one clip in its scene.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneMetrics {
    /// (E8) fraction of frames with at least one vertex inside the scene.
    pub collision_frames: f64,
    /// (E8) fraction of (frame, vertex) pairs inside the scene.
    pub collision_vertices: f64,
    /// (E9) deepest penetration: the largest distance from an inside vertex to the scene's surface (0 without any).
    pub max_penetration: f64,
    /// (E10) fraction of consecutive frame pairs in which a vertex touching the ground at both skates.
    pub foot_skating: f64,
}

/// (E8)–(E10) of `clip` in `scene` (both in the clip's coordinates), measured where the thresholds are stated: in
/// the clip's normalised frame (D1)–(D3), the scene moved with it. An error names the clip when normalising the scene
/// by the clip's frame 0 gives non-finite coordinates.
pub fn clip_scene_metrics(
    clip: &any4d_data::Clip,
    scene: &Scene,
    thresholds: ContactThresholds,
) -> Result<SceneMetrics> {
    let (clip, norm) = any4d_data::preprocess::normalize(clip);
    let scene = scene.normalized(&norm).ok_or_else(|| EvalError::Parameter {
        name: "scene",
        reason: format!("normalising it by {}'s frame 0 gives non-finite coordinates", clip.id),
    })?;
    scene_metrics(Motion::from_clip(&clip)?, &scene, thresholds)
}

/// (E8)–(E10) of `motion` in `scene` (y up, as every clip of the project).
pub fn scene_metrics(motion: Motion, scene: &Scene, thresholds: ContactThresholds) -> Result<SceneMetrics> {
    let (t, n) = (motion.frames(), motion.n_vertices());
    for (name, value) in [("contact", thresholds.contact), ("slide", thresholds.slide)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(EvalError::Parameter {
                name,
                reason: format!("{value}: must be positive and finite"),
            });
        }
    }
    if t < 2 {
        return Err(EvalError::TooFewFrames {
            metric: "scene metrics",
            needed: 2,
            frames: t,
        });
    }
    let sd: Vec<Vec<f64>> = (0..t)
        .into_par_iter()
        .map(|f| {
            motion
                .frame(f)
                .iter()
                .map(|p| signed_distance(scene, p.map(f64::from)))
                .collect()
        })
        .collect();
    let inside: usize = sd.iter().flatten().filter(|&&d| d < 0.0).count();
    let frames_hit = sd.iter().filter(|row| row.iter().any(|&d| d < 0.0)).count();
    let deepest = sd.iter().flatten().fold(0.0f64, |m, &d| m.max(-d));
    let touching = |f: usize, v: usize| sd[f][v].abs() <= thresholds.contact;
    let skating = (0..t - 1)
        .filter(|&f| {
            (0..n).any(|v| {
                let (a, b) = (motion.frame(f)[v], motion.frame(f + 1)[v]);
                let slide = f64::from(b[0] - a[0]).hypot(f64::from(b[2] - a[2]));
                touching(f, v) && touching(f + 1, v) && slide > thresholds.slide
            })
        })
        .count();
    Ok(SceneMetrics {
        collision_frames: frames_hit as f64 / t as f64,
        collision_vertices: inside as f64 / (t * n) as f64,
        max_penetration: deepest,
        foot_skating: skating as f64 / (t - 1) as f64,
    })
}
