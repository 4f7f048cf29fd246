//! Where on the mesh a VAE's reconstruction error lies (P-Table 5 with `--per-vertex`, docs/evaluation.md
//! "Per-vertex errors"): one row per vertex of every reconstructed window, its error over the frames beside
//! features of the ground truth that name a suspect — how far the vertex moves, how far out it sits, how far it is
//! from the nearest latent token, and how close another part of the surface comes (a limb held near the body).
//!
//! All features are in the window's normalised units (frame 0 fills [−1, 1]³ along its longest axis, (D1)–(D3)).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::path::Path;

use any4d_data::Clip;
use any4d_data::io::write_atomic;
use polars::prelude::{Column, DataFrame, ParquetWriter};

use crate::error::{EvalError, Result};
use crate::nearest::{norm, sub};

/// Surface distance (along mesh edges, normalised units) within which another vertex counts as the same part of
/// the surface for [`VertexErrors::gap`]: a tenth of frame 0's longest side.
pub const SAME_PART: f32 = 0.2;

/// The per-vertex error of one reconstruction and the features of its ground truth, one entry per real vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct VertexErrors {
    /// √((1/3T) Σ_t ‖x̂_t,v − x_t,v‖²): the vertex's error over the window, per coordinate as (E1), so the mean of
    /// its square over a window's vertices is the square of the window's (E4) RMSE.
    pub rmse: Vec<f32>,
    /// √((1/T) Σ_t ‖x_t,v − x_0,v‖²): how far the vertex moves from frame 0.
    pub displacement: Vec<f32>,
    /// ‖x_0,v − c‖ / max_u ‖x_0,u − c‖ with c the mean of frame 0: 1 at the farthest vertex (an extremity).
    pub radius: Vec<f32>,
    /// ‖x_0,v − x_0,a‖ for the nearest latent token a (FPS anchor); `None` when the VAE does not say.
    pub token_distance: Option<Vec<f32>>,
    /// The nearest vertex at frame 0 that is more than [`SAME_PART`] away along the surface (or on another
    /// connected part): small for a limb near the body, two fingers, a rider on a mount; `f32::INFINITY` when no
    /// such vertex exists.
    pub gap: Vec<f32>,
    /// Frame 0 of the ground truth, for pictures.
    pub position: Vec<[f32; 3]>,
}

/// Euclidean distance by the metrics' formula ([`norm`] of [`sub`], in f64), as the f32 a feature stores.
fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    norm(sub(a, b)) as f32
}

/// The errors of `rec` against `gt` and `gt`'s features; `anchors` are the VAE's token vertices when known.
///
/// # Shapes
/// `rec`: `[T, N]` rows like `gt.vertices`; `anchors`: indices into `0..N`.
pub fn vertex_errors(gt: &Clip, rec: &[[f32; 3]], anchors: Option<&[u32]>) -> Result<VertexErrors> {
    let (t, n) = (gt.frames, gt.n_vertices);
    if rec.len() != t * n {
        return Err(EvalError::invalid(
            &gt.id,
            "reconstruction",
            format!("{} rows, the window has {t} frames × {n} vertices", rec.len()),
        ));
    }
    if let Some(&a) = anchors.and_then(|a| a.iter().find(|&&a| a as usize >= n)) {
        return Err(EvalError::invalid(
            &gt.id,
            "anchors",
            format!("token vertex {a} is outside the {n} vertices"),
        ));
    }
    let x0 = gt.frame(0);
    // Summed in f64 as (E1) sums.
    let rms = |d: &dyn Fn(usize, usize) -> f64, per: f64| -> Vec<f32> {
        (0..n)
            .map(|v| ((0..t).map(|f| d(f, v).powi(2)).sum::<f64>() / (per * t.max(1) as f64)).sqrt() as f32)
            .collect()
    };
    let rmse = rms(&|f, v| norm(sub(rec[f * n + v], gt.vertices[f * n + v])), 3.0);
    let displacement = rms(&|f, v| norm(sub(gt.vertices[f * n + v], x0[v])), 1.0);
    let mut c = [0.0f32; 3];
    for p in x0 {
        for (ck, pk) in c.iter_mut().zip(p) {
            *ck += pk / n.max(1) as f32;
        }
    }
    let r: Vec<f32> = x0.iter().map(|&p| dist(p, c)).collect();
    let r_max = r.iter().copied().fold(0.0f32, f32::max).max(f32::MIN_POSITIVE);
    let radius = r.iter().map(|v| v / r_max).collect();
    let token_distance = anchors.map(|a| {
        x0.iter()
            .map(|&p| a.iter().map(|&i| dist(p, x0[i as usize])).fold(f32::INFINITY, f32::min))
            .collect()
    });
    Ok(VertexErrors {
        rmse,
        displacement,
        radius,
        token_distance,
        gap: gaps(x0, &gt.faces, SAME_PART),
        position: x0.to_vec(),
    })
}

/// For every vertex of `x`, the distance to the nearest vertex farther than `same_part` along the mesh's edges
/// (Dijkstra bounded at `same_part`; a vertex of another connected part is always farther; vertices at exactly one
/// position, as a texture seam leaves them, are joined).
fn gaps(x: &[[f32; 3]], faces: &[[u32; 3]], same_part: f32) -> Vec<f32> {
    let n = x.len();
    let mut adjacency: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            if a != b && (a as usize) < n && (b as usize) < n {
                adjacency[a as usize].push(b);
                adjacency[b as usize].push(a);
            }
        }
    }
    // Vertices at one position (a texture seam splits a vertex in two) are one point of the surface.
    let mut by_position: Vec<u32> = (0..n as u32).collect();
    let key = |i: &u32| x[*i as usize].map(f32::to_bits);
    by_position.sort_unstable_by_key(key);
    for pair in by_position.windows(2) {
        if key(&pair[0]) == key(&pair[1]) {
            adjacency[pair[0] as usize].push(pair[1]);
            adjacency[pair[1] as usize].push(pair[0]);
        }
    }
    for a in &mut adjacency {
        a.sort_unstable();
        a.dedup();
    }
    let mut reached = vec![f32::INFINITY; n];
    let mut touched = Vec::new();
    (0..n)
        .map(|v| {
            // Bounded Dijkstra from v: every vertex within `same_part` along the surface.
            let mut heap = BinaryHeap::new();
            reached[v] = 0.0;
            touched.push(v);
            heap.push(Near(0.0, v as u32));
            while let Some(Near(d, u)) = heap.pop() {
                if d > reached[u as usize] {
                    continue;
                }
                for &w in &adjacency[u as usize] {
                    let dw = d + dist(x[u as usize], x[w as usize]);
                    if dw <= same_part && dw < reached[w as usize] {
                        if reached[w as usize].is_infinite() {
                            touched.push(w as usize);
                        }
                        reached[w as usize] = dw;
                        heap.push(Near(dw, w));
                    }
                }
            }
            let gap = (0..n)
                .filter(|&u| reached[u].is_infinite())
                .map(|u| dist(x[v], x[u]))
                .fold(f32::INFINITY, f32::min);
            for u in touched.drain(..) {
                reached[u] = f32::INFINITY;
            }
            gap
        })
        .collect()
}

/// A heap entry ordered by smallest distance first.
#[derive(PartialEq)]
struct Near(f32, u32);

impl Eq for Near {}

impl PartialOrd for Near {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Near {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// One reconstructed window's rows: which VAE, which manifest item.
pub struct VertexRecord {
    pub method: String,
    pub item: usize,
    pub clip_id: String,
    pub errors: VertexErrors,
}

/// Write `records` as `vertices.parquet`: columns `method`, `item`, `clip_id`, `vertex`, `rmse`, `displacement`,
/// `radius`, `token_distance` (null when the VAE did not say), `gap` (null when no vertex is farther than
/// [`SAME_PART`] along the surface), `x`, `y`, `z` (frame 0).
pub fn write_vertex_parquet(records: &[VertexRecord], path: &Path) -> Result<()> {
    let rows = || {
        records
            .iter()
            .flat_map(|r| (0..r.errors.rmse.len()).map(move |v| (r, v)))
    };
    let f32s = |get: &dyn Fn(&VertexErrors, usize) -> f32| rows().map(|(r, v)| get(&r.errors, v)).collect::<Vec<_>>();
    let cols = vec![
        Column::new(
            "method".into(),
            rows().map(|(r, _)| r.method.as_str()).collect::<Vec<_>>(),
        ),
        Column::new("item".into(), rows().map(|(r, _)| r.item as u32).collect::<Vec<_>>()),
        Column::new(
            "clip_id".into(),
            rows().map(|(r, _)| r.clip_id.as_str()).collect::<Vec<_>>(),
        ),
        Column::new("vertex".into(), rows().map(|(_, v)| v as u32).collect::<Vec<_>>()),
        Column::new("rmse".into(), f32s(&|e, v| e.rmse[v])),
        Column::new("displacement".into(), f32s(&|e, v| e.displacement[v])),
        Column::new("radius".into(), f32s(&|e, v| e.radius[v])),
        Column::new(
            "token_distance".into(),
            rows()
                .map(|(r, v)| r.errors.token_distance.as_ref().map(|d| d[v]))
                .collect::<Vec<_>>(),
        ),
        Column::new(
            "gap".into(),
            rows()
                .map(|(r, v)| Some(r.errors.gap[v]).filter(|g| g.is_finite()))
                .collect::<Vec<_>>(),
        ),
        Column::new("x".into(), f32s(&|e, v| e.position[v][0])),
        Column::new("y".into(), f32s(&|e, v| e.position[v][1])),
        Column::new("z".into(), f32s(&|e, v| e.position[v][2])),
    ];
    let len = rows().count();
    let mut df = DataFrame::new(len, cols).map_err(|e| EvalError::invalid(path, "dataframe", e.to_string()))?;
    let mut buf = Vec::new();
    ParquetWriter::new(&mut buf)
        .finish(&mut df)
        .map_err(|e| EvalError::invalid(path, "parquet", e.to_string()))?;
    Ok(write_atomic(path, &buf)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit triangles side by side in x, `apart` from each other, not joined: T frames, the second moving.
    fn two_parts(apart: f32, frames: usize) -> Clip {
        let tri = |x0: f32| [[x0, 0.0, 0.0], [x0 + 0.1, 0.0, 0.0], [x0, 0.1, 0.0]];
        let mut vertices = Vec::new();
        for f in 0..frames {
            let mut frame: Vec<[f32; 3]> = tri(0.0).into_iter().chain(tri(0.1 + apart)).collect();
            for p in &mut frame[3..] {
                p[2] += 0.3 * f as f32;
            }
            vertices.extend(frame);
        }
        Clip::new("two", vertices, frames, 6, vec![[0, 1, 2], [3, 4, 5]], "", "test").unwrap()
    }

    #[test]
    fn the_features_of_two_separate_triangles() {
        let gt = two_parts(0.05, 3);
        let mut rec = gt.vertices.clone();
        for f in 0..3 {
            rec[f * 6][0] += 0.2; // vertex 0 off by 0.2 in every frame
        }
        let e = vertex_errors(&gt, &rec, Some(&[0])).unwrap();
        // Off by 0.2 in one coordinate: per coordinate as (E1), √(0.04 / 3).
        let off = (0.04f32 / 3.0).sqrt();
        assert!(
            (e.rmse[0] - off).abs() < 1e-6 && e.rmse[1..].iter().all(|&r| r == 0.0),
            "{:?}",
            e.rmse
        );
        // The second part moves 0, 0.3, 0.6 in z: √((0 + 0.09 + 0.36) / 3).
        let moving = (0.45f32 / 3.0).sqrt();
        assert!(e.displacement[..3].iter().all(|&d| d == 0.0));
        assert!(
            e.displacement[3..].iter().all(|&d| (d - moving).abs() < 1e-6),
            "{:?}",
            e.displacement
        );
        // The other triangle is another part: vertex 1 (x = 0.1) is 0.05 from vertex 3 (x = 0.15).
        assert!(
            (e.gap[1] - 0.05).abs() < 1e-6 && (e.gap[3] - 0.05).abs() < 1e-6,
            "{:?}",
            e.gap
        );
        let token = e.token_distance.unwrap();
        assert_eq!(token[0], 0.0);
        assert!((token[1] - 0.1).abs() < 1e-6);
        assert_eq!(e.radius.iter().copied().fold(0.0, f32::max), 1.0);
        let farthest = e.radius.iter().position(|&r| r == 1.0).unwrap();
        assert!(
            farthest == 0 || farthest == 4,
            "an outer corner is the extremity, got {farthest}"
        );
    }

    #[test]
    fn a_vertex_far_along_the_surface_counts_and_a_near_one_does_not() {
        // A strip folded back on itself: 0 → 1 → 2 along x, then 3 above 0 reached only through 2 (a long way round).
        let x = [
            [0.0, 0.0, 0.0],
            [0.15, 0.0, 0.0],
            [0.3, 0.0, 0.0],
            [0.0, 0.05, 0.0],
            [0.15, 0.025, 0.0],
        ];
        let faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4]];
        // Vertex 4 joins all, so every vertex is within 0.2 of 4, but 0 → 3 goes 0 → 4 → 3: ≈ 0.152 + 0.152 > 0.2.
        let g = gaps(&x, &faces, 0.2);
        assert!((g[0] - 0.05).abs() < 1e-6, "0 sees 3 as another part: {g:?}");
        assert!(g[4].is_infinite(), "4 reaches every vertex within 0.2: {g:?}");
        let alone = gaps(&x[..1], &[], 0.2);
        assert!(alone[0].is_infinite());
        // A seam: vertex 5 sits on vertex 0 and belongs to a triangle of its own; it is 0's surface, not a gap of 0.
        let seam = [x[0], x[1], x[2], x[3], x[4], x[0], [0.0, -0.1, 0.0], [0.1, -0.1, 0.0]];
        let g = gaps(&seam, &[[0, 1, 4], [1, 2, 4], [2, 3, 4], [5, 6, 7]], 0.2);
        assert!((g[0] - 0.05).abs() < 1e-6 && (g[5] - 0.05).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn mismatched_reconstructions_and_anchors_are_named() {
        let gt = two_parts(0.05, 2);
        let e = vertex_errors(&gt, &gt.vertices[..5], None).unwrap_err();
        assert!(e.to_string().contains("reconstruction"), "{e}");
        let e = vertex_errors(&gt, &gt.vertices, Some(&[6])).unwrap_err();
        assert!(e.to_string().contains("token vertex 6"), "{e}");
    }

    #[test]
    fn the_parquet_has_one_row_per_vertex_and_nulls_where_unknown() {
        let gt = two_parts(5.0, 2);
        let e = vertex_errors(&gt, &gt.vertices, None).unwrap();
        assert!(
            e.gap.iter().all(|g| (g - 5.0).abs() < 0.2),
            "parts 5 apart: {:?}",
            e.gap
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("vertices.parquet");
        let rec = |item| VertexRecord {
            method: "vae".into(),
            item,
            clip_id: "two".into(),
            errors: e.clone(),
        };
        write_vertex_parquet(&[rec(0), rec(1)], &path).unwrap();
        use polars::prelude::{ParquetReader, SerReader};
        let df = ParquetReader::new(std::fs::File::open(&path).unwrap())
            .finish()
            .unwrap();
        assert_eq!(df.height(), 12);
        assert_eq!(df.column("token_distance").unwrap().null_count(), 12);
        assert_eq!(df.column("gap").unwrap().null_count(), 0);
    }
}
