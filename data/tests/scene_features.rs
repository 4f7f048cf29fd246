//! Scene features (docs/method.md §4.11, (S1)–(S2)): the occupancy grid and basis-point offsets worked out by hand on
//! a floor and a box, their bad input, and agreement with an independent numpy version
//! (`scripts/scene_features_reference.py`).

use std::path::Path;

use any4d_data::scene::Scene;
use any4d_data::scene::features::{GridSpec, MAX_GRID_CELLS, bps_offsets, occupancy_grid};

/// A floor slab whose top is y = −1 and a box [0.3, 0.8] × [−1, 0.2] × [−0.4, 0.4] standing on it.
fn room() -> Scene {
    Scene::cuboid([-3.0, -1.3, -3.0], [3.0, -1.0, 3.0]).with(&Scene::cuboid([0.3, -1.0, -0.4], [0.8, 0.2, 0.4]))
}

#[test]
fn a_floor_fills_the_bottom_layer_of_the_grid_and_nothing_else() {
    let floor = Scene::cuboid([-3.0, -1.3, -3.0], [3.0, -1.0, 3.0]);
    let spec = GridSpec::default();
    let grid = occupancy_grid(&floor, [0.0; 3], &spec).unwrap();
    assert_eq!(grid.len(), 16 * 8 * 16);
    let [_, gy, gz] = spec.cells;
    // Cell centres at y = −0.875, −0.625, …: the floor's top (y = −1) is 0.125 below the first layer, inside the
    // circumscribed radius 0.25·√3/2 ≈ 0.217; the second layer is 0.375 above it.
    for (n, &o) in grid.iter().enumerate() {
        let j = (n / gz) % gy;
        assert_eq!(o, if j == 0 { 1.0 } else { 0.0 }, "cell {n} (layer {j})");
    }
    let moved = occupancy_grid(&floor, [0.0, 0.5, 0.0], &spec).unwrap();
    assert!(
        moved.iter().all(|&o| o == 0.0),
        "a grid centred higher does not reach the floor"
    );
}

#[test]
fn a_box_occupies_the_cells_its_solid_reaches() {
    let scene = room();
    let spec = GridSpec {
        cells: [8, 4, 8],
        cell: 0.5,
    };
    let grid = occupancy_grid(&scene, [0.0; 3], &spec).unwrap();
    let [_, gy, gz] = spec.cells;
    let at = |i: usize, j: usize, k: usize| grid[(i * gy + j) * gz + k];
    // Cell centres x, z ∈ {−1.75, …, 1.75}, y ∈ {−0.75, −0.25, 0.25, 0.75}. (0.25, −0.25, 0.25) is 0.05 from the
    // box's face x = 0.3: occupied; (0.75, 0.25, 0.25) is 0.05 above its top: occupied; (−1.25, 0.25, 0.25) is far from both.
    assert_eq!(at(4, 1, 4), 1.0);
    assert_eq!(at(5, 2, 4), 1.0);
    assert_eq!(at(1, 2, 4), 0.0);
    assert_eq!(at(1, 0, 4), 1.0, "the floor layer");
    assert_eq!(at(4, 3, 4), 0.0, "above the box (top at 0.2, centre 0.75)");
}

#[test]
fn offsets_point_from_each_vertex_to_the_nearest_scene_point() {
    let scene = room();
    let points = [[-1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [0.0, -1.0, 2.0]];
    let got = bps_offsets(&scene, &points).unwrap();
    let want = [[0.0, -1.0, 0.0], [0.0, -0.3, 0.0], [-0.2, 0.0, 0.0], [0.0, 0.0, 0.0]];
    for ((g, w), p) in got.iter().zip(&want).zip(&points) {
        for a in 0..3 {
            assert!((g[a] - w[a]).abs() < 1e-6, "{p:?}: {g:?} vs {w:?}");
        }
    }
}

#[test]
fn bad_grids_centres_and_points_are_refused() {
    let scene = room();
    for cells in [[0, 8, 16], [65, 8, 16], [64, 64, 64]] {
        let spec = GridSpec { cells, cell: 0.25 };
        let e = occupancy_grid(&scene, [0.0; 3], &spec).unwrap_err();
        assert_eq!(e.field, "cells", "{cells:?}");
    }
    assert!(
        GridSpec {
            cells: [64, 16, 64],
            cell: 0.1
        }
        .len()
            <= MAX_GRID_CELLS
    );
    for cell in [0.0, -0.25, f32::NAN, f32::INFINITY] {
        let spec = GridSpec {
            cell,
            ..GridSpec::default()
        };
        assert_eq!(
            occupancy_grid(&scene, [0.0; 3], &spec).unwrap_err().field,
            "cell",
            "{cell}"
        );
    }
    let e = occupancy_grid(&scene, [0.0, f32::NAN, 0.0], &GridSpec::default()).unwrap_err();
    assert_eq!(e.field, "center");
    let e = bps_offsets(&scene, &[[0.0; 3], [f32::INFINITY, 0.0, 0.0]]).unwrap_err();
    assert!(e.reason.contains("point 1"), "{e}");
}

#[test]
fn the_features_agree_with_an_independent_numpy_version() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    let scene = room();
    let spec = GridSpec {
        cells: [12, 6, 10],
        cell: 0.3,
    };
    let center = [0.1, -0.2, 0.05];
    let points: Vec<[f32; 3]> = (0..50)
        .map(|i| {
            let t = i as f32;
            [
                1.2 * (0.37 * t).sin(),
                1.1 * (0.23 * t).cos() - 0.3,
                0.9 * (0.51 * t).sin(),
            ]
        })
        .collect();
    let grid = occupancy_grid(&scene, center, &spec).unwrap();
    let offsets = bps_offsets(&scene, &points).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("input.json");
    let json = serde_json::json!({
        "vertices": scene.vertices, "faces": scene.faces, "cells": spec.cells, "cell": spec.cell,
        "center": center, "points": points,
    });
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/scene_features_reference.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(&input)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let theirs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let their_grid: Vec<f32> = serde_json::from_value(theirs["grid"].clone()).unwrap();
    assert_eq!(grid, their_grid);
    let filled = grid.iter().filter(|&&o| o == 1.0).count();
    assert!(
        filled > 20 && filled < grid.len() / 2,
        "{filled} filled: a comparison of something"
    );
    let their_offsets: Vec<[f32; 3]> = serde_json::from_value(theirs["offsets"].clone()).unwrap();
    for (i, (a, b)) in offsets.iter().zip(&their_offsets).enumerate() {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-5, "point {i}: {a:?} vs numpy {b:?}");
        }
    }
}
