//! What a scene-aware model is told about the scene (docs/method.md §4.11): a coarse occupancy grid around frame 0
//! (S1), SceneMI's global feature for any mesh, and basis-point offsets from anchor vertices to the nearest scene
//! point (S2), its local feature at keyframes. Both are in the clip's normalised frame (D1)–(D3), the scene moved with
//! the clip.

use rayon::prelude::*;

use super::Scene;
use super::geometry::{nearest_point, signed_distance};
use crate::error::{DataError, Result};

/// Most cells of an occupancy grid (64³ / 4).
pub const MAX_GRID_CELLS: usize = 1 << 16;

/// The occupancy grid's layout: `cells` = (G_x, G_y, G_z) cubes of side `cell` centred on frame 0's bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    pub cells: [usize; 3],
    pub cell: f32,
}

impl Default for GridSpec {
    /// 16 × 8 × 16 cells of 0.25: x and z in ±2, y in ±1 around frame 0's centre, twice the normalised half-extent of
    /// frame 0 across the ground and once up and down (y is up).
    fn default() -> Self {
        GridSpec {
            cells: [16, 8, 16],
            cell: 0.25,
        }
    }
}

impl GridSpec {
    /// Every cell count in 1..=64, at most [`MAX_GRID_CELLS`] cells, a finite positive cell side.
    pub fn validate(&self) -> Result<()> {
        let bad = |reason: String| Err(DataError::new("scene grid", "cells", reason));
        if let Some(n) = self.cells.iter().find(|&&n| !(1..=64).contains(&n)) {
            return bad(format!("{n} cells along an axis; each must be 1..=64"));
        }
        if self.len() > MAX_GRID_CELLS {
            return bad(format!("{} cells, more than {MAX_GRID_CELLS}", self.len()));
        }
        if !(self.cell.is_finite() && self.cell > 0.0) {
            return Err(DataError::new(
                "scene grid",
                "cell",
                format!("{} is not a finite positive side", self.cell),
            ));
        }
        Ok(())
    }

    /// G_x · G_y · G_z.
    pub fn len(&self) -> usize {
        self.cells.iter().product()
    }

    /// Whether the grid has no cell (never, once validated).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The centre of cell (i, j, k) of a grid centred on `center`.
    pub fn cell_center(&self, center: [f32; 3], ijk: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|a| {
            f64::from(center[a]) + f64::from(self.cell) * (ijk[a] as f64 - (self.cells[a] as f64 - 1.0) / 2.0)
        })
    }
}

/// (S1) the occupancy grid of `scene` around `center` (frame 0's bounding-box centre): cell (i, j, k), at index
/// (i · G_y + j) · G_z + k, is 1 when the scene's solid reaches its circumscribed ball — the centre's signed distance
/// to the scene is at most h·√3/2 (inside, or a surface passing through the cell) — and 0 otherwise.
///
/// # Shapes
/// Returns `[G_x · G_y · G_z]`.
pub fn occupancy_grid(scene: &Scene, center: [f32; 3], spec: &GridSpec) -> Result<Vec<f32>> {
    spec.validate()?;
    if center.iter().any(|c| !c.is_finite()) {
        return Err(DataError::new(
            "scene grid",
            "center",
            format!("{center:?} is not finite"),
        ));
    }
    let [_, gy, gz] = spec.cells;
    let reach = f64::from(spec.cell) * 3f64.sqrt() / 2.0;
    Ok((0..spec.len())
        .into_par_iter()
        .map(|n| {
            let q = spec.cell_center(center, [n / (gy * gz), (n / gz) % gy, n % gz]);
            if signed_distance(scene, q) <= reach { 1.0 } else { 0.0 }
        })
        .collect())
}

/// (S2) the basis-point offsets of `points` (a keyframe's anchor vertices): for each, the nearest point of the
/// scene's surface minus the point, so a vertex resting on the floor has an offset of length ~0 and one above it
/// points down.
///
/// # Shapes
/// `points`: `[P]`; returns `[P]`.
pub fn bps_offsets(scene: &Scene, points: &[[f32; 3]]) -> Result<Vec<[f32; 3]>> {
    if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(DataError::new(
            "scene offsets",
            "points",
            format!("point {i} = {:?} is not finite", points[i]),
        ));
    }
    Ok(points
        .par_iter()
        .map(|p| {
            let x = p.map(f64::from);
            let q = nearest_point(scene, x);
            std::array::from_fn(|a| (q[a] - x[a]) as f32)
        })
        .collect())
}

/// The centre of a frame's bounding box: where (S1)'s grid is centred (frame 0 of a clip).
pub fn frame_center(frame: &[[f32; 3]]) -> [f32; 3] {
    let (lo, hi) = crate::preprocess::bounds(frame);
    std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0)
}

/// (S1) and (S2) of one clip in its scene, everything a scene-aware network may be told.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipSceneFeatures {
    /// The occupancy grid around frame 0's centre, `[G]` in (S1)'s cell order.
    pub grid: Vec<f32>,
    /// The offsets of the anchor vertices at every frame, `[T, P, 3]` row-major (keyframes are chosen later).
    pub offsets: Vec<f32>,
}

/// [`occupancy_grid`] around frame 0's bounding-box centre and [`bps_offsets`] of the vertices `anchors` (the VAE's
/// FPS tokens, docs/method.md §2.5) at every frame of `clip`; an anchor past the clip's vertices is refused.
pub fn clip_scene_features(
    clip: &crate::clip::Clip,
    scene: &Scene,
    anchors: &[u32],
    spec: &GridSpec,
) -> Result<ClipSceneFeatures> {
    if let Some(&a) = anchors.iter().find(|&&a| a as usize >= clip.n_vertices) {
        return Err(DataError::new(
            &clip.id,
            "scene anchors",
            format!("anchor vertex {a} is past the clip's {} vertices", clip.n_vertices),
        ));
    }
    let grid = occupancy_grid(scene, frame_center(clip.frame(0)), spec)?;
    let mut offsets = Vec::with_capacity(clip.frames * anchors.len() * 3);
    for f in 0..clip.frames {
        let frame = clip.frame(f);
        let points: Vec<[f32; 3]> = anchors.iter().map(|&a| frame[a as usize]).collect();
        offsets.extend(bps_offsets(scene, &points)?.into_iter().flatten());
    }
    Ok(ClipSceneFeatures { grid, offsets })
}
