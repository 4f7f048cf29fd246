//! Nearest-neighbour distances for Chamfer (docs/method.md (E2)): a k-d tree for any two sets, and for two frames
//! of one mesh a uniform cell grid searched only around each point's same-index vertex.
//!
//! Neighbours are chosen by squared distances computed in f32 (the coordinates as stored) and their distances then
//! computed in f64. Against an f64 search the neighbour can differ only between points whose squared distances
//! agree to f32 rounding, so each distance is within that rounding of the exact nearest one (relative 1e-7), far
//! below the metric's decimals; where squared differences underflow f32 (points closer than about 1e-19), within
//! 1e-18 absolute. Between candidates tied in f32 either may be chosen. Coordinates beyond ±1e18, whose squared
//! differences could overflow f32, are refused.

use std::cell::OnceCell;
use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::error::{EvalError, Result};

/// `a − b` in f64.
pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [
        f64::from(a[0]) - f64::from(b[0]),
        f64::from(a[1]) - f64::from(b[1]),
        f64::from(a[2]) - f64::from(b[2]),
    ]
}

/// The Euclidean norm.
pub(crate) fn norm(d: [f64; 3]) -> f64 {
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Squared distance in f32, the one formula every search here compares with.
fn dist2(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Euclidean distance in f64, as the other metrics compute it.
fn dist(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    norm(sub(*a, *b))
}

/// The radius around a query that holds every point whose f32 squared distance is below `best`: f32 rounding of
/// that distance is relative (≈ 2.4e-7, covered by the factor) except where squares underflow (covered by the
/// absolute term, about 8.5 times the smallest normal f32).
fn search_radius(best: f32) -> f64 {
    (f64::from(best) + 1e-37).sqrt() * (1.0 + 1e-5)
}

/// The largest coordinate magnitude searched: three squared differences of points within ±1e18 stay below f32's
/// largest value (3.4e38).
const MAX_COORDINATE: f32 = 1e18;

/// The most cells (a 3 × 3 × 3 block) that [`CellGrid::nearest_below`] searches before it leaves the query to the
/// k-d tree. A prediction near the truth needs one to eight cells of about one point each; a far one is the tree's
/// case, whose cost grows with the logarithm of the set rather than with the box.
const MAX_CELLS: usize = 27;

/// The most points that [`CellGrid::nearest_below`] scans before it leaves the query to the k-d tree: a set whose
/// bounding box one outlying vertex stretches can put most of its points into a few cells, and scanning those for
/// every query would be quadratic.
const MAX_POINTS: usize = 128;

/// A uniform grid over a point set, about one point per cell of its bounding box (a flat axis gets at least
/// 1/64 of the longest one's extent), the points sorted by cell so that a row of cells along x is one slice.
pub(crate) struct CellGrid {
    lo: [f64; 3],
    /// Cells per unit length (0 when every point is the same: one cell).
    inv: f64,
    dims: [usize; 3],
    /// Cell `c`'s points are `points[start[c]..start[c + 1]]`; cells are numbered x fastest, then y, then z.
    start: Vec<u32>,
    points: Vec<[f32; 3]>,
    /// Each sorted point's index in the input set.
    index: Vec<u32>,
}

impl CellGrid {
    /// The grid over `set` (finite coordinates, at most `u32::MAX` points: the callers check both).
    pub(crate) fn new(set: &[[f32; 3]]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in set {
            for k in 0..3 {
                lo[k] = lo[k].min(f64::from(p[k]));
                hi[k] = hi[k].max(f64::from(p[k]));
            }
        }
        let extent = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(0.0));
        let longest = extent.iter().copied().fold(0.0, f64::max);
        let (mut dims, mut inv) = ([1usize; 3], 0.0);
        if longest > 0.0 {
            let volume: f64 = extent.iter().map(|&e| e.max(longest / 64.0)).product();
            inv = 1.0 / (volume / set.len() as f64).cbrt();
            // At most 1024 cells per axis; the product stays within a small multiple of the point count.
            dims = extent.map(|e| ((e * inv).floor() as usize).saturating_add(1).min(1024));
        }
        let cell_of = |p: &[f32; 3]| -> usize {
            let c = [0, 1, 2].map(|k| (((f64::from(p[k]) - lo[k]) * inv) as usize).min(dims[k] - 1));
            (c[2] * dims[1] + c[1]) * dims[0] + c[0]
        };
        let cells: Vec<usize> = set.iter().map(cell_of).collect();
        let mut start = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for c in 1..start.len() {
            start[c] += start[c - 1];
        }
        let mut next = start.clone();
        let (mut points, mut index) = (vec![[0.0; 3]; set.len()], vec![0u32; set.len()]);
        for (i, &c) in cells.iter().enumerate() {
            let slot = next[c] as usize;
            next[c] += 1;
            points[slot] = set[i];
            index[slot] = i as u32;
        }
        Self {
            lo,
            inv,
            dims,
            start,
            points,
            index,
        }
    }

    /// The point nearest to `p` among those whose f32 squared distance is below `best`, else `candidate` (the
    /// point at `best`). `None` when the cells within [`search_radius`] of `p` (widened for rounding, below) are
    /// more than [`MAX_CELLS`] or hold more than [`MAX_POINTS`].
    pub(crate) fn nearest_below(&self, p: &[f32; 3], mut best: f32, mut candidate: usize) -> Option<usize> {
        if best == 0.0 {
            return Some(candidate);
        }
        let r = search_radius(best);
        // A point within r of p along axis k lands in a cell of this range. p − lo and each stored point's q − lo
        // are each rounded once in f64, so they can sit up to about one f64 epsilon of |lo|, |p| and r further
        // apart than the points; the range's ends are widened by four times that, and rounding (± reach, · inv,
        // the floor) is monotone from there on.
        let range = |k: usize| {
            let last = (self.dims[k] - 1) as f64;
            let cell = |x: f64| (x * self.inv).clamp(0.0, last) as usize;
            let x = f64::from(p[k]) - self.lo[k];
            let reach = r + 4.0 * f64::EPSILON * (self.lo[k].abs() + f64::from(p[k]).abs() + r);
            (cell(x - reach), cell(x + reach))
        };
        let ((x0, x1), (y0, y1), (z0, z1)) = (range(0), range(1), range(2));
        if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > MAX_CELLS {
            return None;
        }
        let mut scanned = 0;
        for z in z0..=z1 {
            for y in y0..=y1 {
                let row = (z * self.dims[1] + y) * self.dims[0];
                let cells = self.start[row + x0] as usize..self.start[row + x1 + 1] as usize;
                scanned += cells.len();
                if scanned > MAX_POINTS {
                    return None;
                }
                for (q, &j) in self.points[cells.clone()].iter().zip(&self.index[cells]) {
                    let d2 = dist2(p, q);
                    if d2 < best {
                        best = d2;
                        candidate = j as usize;
                    }
                }
            }
        }
        Some(candidate)
    }
}

/// Mean nearest-neighbour distance from each point of `from` to the set `to` (non-empty, finite).
///
/// `paired`: `from` and `to` are two frames of one mesh (the same vertex count and order), so the point of `to` with
/// the query's own index bounds its nearest distance from above: only points nearer than it are searched for, in a
/// [`CellGrid`] while they fit a few cells of few points (a prediction near the truth), else in a k-d tree within
/// that bound (a
/// k-nearest search with a radius keeps one candidate, where a radius search would gather every point of a wide
/// ball). Any bound gives the unbounded search's distance: the nearest point lies within every bound that holds a
/// point. The tree's bound is loosened like [`search_radius`] so that rounding cannot leave the same-index point
/// outside it; should it still come back empty, the search is repeated unbounded.
pub(crate) fn mean_nearest(from: &[[f32; 3]], to: &[[f32; 3]], paired: bool) -> Result<f64> {
    if to.len() > u32::MAX as usize {
        return Err(EvalError::Parameter {
            name: "nearest-neighbour set",
            reason: format!("{} points, more than {} can be searched", to.len(), u32::MAX),
        });
    }
    let largest = from.iter().chain(to).flatten().fold(0.0f32, |m, x| m.max(x.abs()));
    if largest > MAX_COORDINATE {
        return Err(EvalError::Parameter {
            name: "nearest-neighbour set",
            reason: format!(
                "a coordinate of magnitude {largest:e} exceeds {MAX_COORDINATE:e}: squared distances would overflow f32"
            ),
        });
    }
    let tree: OnceCell<ImmutableKdTree<f32, 3>> = OnceCell::new();
    let tree = || -> Result<&ImmutableKdTree<f32, 3>> {
        if let Some(t) = tree.get() {
            return Ok(t);
        }
        let built = ImmutableKdTree::new_from_slice(to).map_err(|e| EvalError::Parameter {
            name: "nearest-neighbour set",
            reason: e.to_string(),
        })?;
        Ok(tree.get_or_init(|| built))
    };
    let unbounded = |p: &[f32; 3]| -> Result<usize> {
        Ok(tree()?.query(p).nearest_one::<SquaredEuclidean<f32>>().execute().item as usize)
    };
    let grid = paired.then(|| CellGrid::new(to));
    let mut sum = 0.0;
    for (i, p) in from.iter().enumerate() {
        let nearest = match (&grid, to.get(i)) {
            (Some(grid), Some(same)) => {
                let bound = dist2(p, same);
                match grid.nearest_below(p, bound, i) {
                    Some(j) => j,
                    None => {
                        let within = tree()?
                            .query(p)
                            .nearest_n::<SquaredEuclidean<f32>>(NonZeroUsize::MIN)
                            .within(bound * (1.0 + 1e-5) + f32::MIN_POSITIVE)
                            .execute();
                        match within.first() {
                            Some(r) => r.item as usize,
                            None => unbounded(p)?,
                        }
                    }
                }
            }
            _ => unbounded(p)?,
        };
        sum += dist(p, &to[nearest]);
    }
    Ok(sum / from.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift), so the cases need no crate.
    struct Gen(u64);

    impl Gen {
        fn unit(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
        fn points(&mut self, n: usize, scale: [f32; 3]) -> Vec<[f32; 3]> {
            (0..n).map(|_| [0, 1, 2].map(|k| self.unit() * scale[k])).collect()
        }
    }

    /// The mean over `from` of the f64 distance to the nearest point of `to`, every pair compared.
    fn brute_mean(from: &[[f32; 3]], to: &[[f32; 3]]) -> f64 {
        let nearest = |p: &[f32; 3]| to.iter().map(|q| dist(p, q)).fold(f64::INFINITY, f64::min);
        from.iter().map(nearest).sum::<f64>() / from.len() as f64
    }

    /// Sets of one mesh's frames that a grid handles badly or oddly: flat, a line, one repeated point, two far
    /// clusters, huge and small coordinates, a single point; and predictions near, moderately and far off.
    fn cases() -> Vec<(&'static str, Vec<[f32; 3]>)> {
        let mut g = Gen(0x9e37_79b9_7f4a_7c15);
        let mut clusters = g.points(300, [0.01; 3]);
        for p in &mut clusters[150..] {
            p[0] += 1e4;
        }
        vec![
            ("cloud", g.points(500, [1.0; 3])),
            ("plane", g.points(500, [1.0, 1.0, 0.0])),
            ("line", g.points(200, [0.0, 3.0, 0.0])),
            ("one point repeated", vec![[0.5, -2.0, 7.0]; 50]),
            ("two far clusters", clusters),
            ("huge", g.points(300, [1e17; 3])),
            ("small", g.points(300, [1e-12; 3])),
            ("single", vec![[1.0, 2.0, 3.0]]),
        ]
    }

    #[test]
    fn the_paired_search_finds_the_brute_force_nearest_distance() {
        let mut g = Gen(7);
        let mut grid_answers = 0;
        for (name, to) in cases() {
            let extent = to
                .iter()
                .flatten()
                .fold(0.0f32, |m, x| m.max(x.abs()))
                .max(f32::MIN_POSITIVE);
            for noise in [0.0, 1e-4, 0.02, 0.3, 3.0] {
                let from: Vec<[f32; 3]> = to
                    .iter()
                    .map(|q| [0, 1, 2].map(|k| q[k] + g.unit() * noise * extent))
                    .collect();
                let expected = brute_mean(&from, &to);
                let got = mean_nearest(&from, &to, true).expect("finite sets");
                let tolerance = 1e-6 * expected + 1e-30;
                assert!(
                    (got - expected).abs() <= tolerance,
                    "{name}, noise {noise}: {got} vs {expected}"
                );
                let grid = CellGrid::new(&to);
                grid_answers += from
                    .iter()
                    .enumerate()
                    .filter(|&(i, p)| grid.nearest_below(p, dist2(p, &to[i]), i).is_some())
                    .count();
            }
        }
        // Both paths ran: the grid for near predictions, the tree for far ones.
        let total: usize = cases().iter().map(|(_, s)| s.len() * 5).sum();
        assert!(
            grid_answers > total / 4 && grid_answers < total,
            "{grid_answers} of {total}"
        );
    }

    #[test]
    fn the_grid_answers_exactly_the_f32_nearest_when_it_answers() {
        let mut g = Gen(11);
        for (name, to) in cases() {
            let grid = CellGrid::new(&to);
            let extent = to
                .iter()
                .flatten()
                .fold(0.0f32, |m, x| m.max(x.abs()))
                .max(f32::MIN_POSITIVE);
            let (mut asked, mut answered) = (0, 0);
            for noise in [1e-3, 0.02, 0.1] {
                // Near each vertex, starting from it, as the paired search starts from the same-index one.
                for (i, q) in to.iter().enumerate() {
                    let p = q.map(|c| c + g.unit() * noise * extent);
                    let best = to.iter().map(|t| dist2(&p, t)).fold(f32::INFINITY, f32::min);
                    asked += 1;
                    if let Some(j) = grid.nearest_below(&p, dist2(&p, q), i) {
                        answered += 1;
                        assert_eq!(dist2(&p, &to[j]), best, "{name}: query {p:?}");
                    }
                }
            }
            if matches!(name, "cloud" | "plane" | "line") {
                assert!(answered * 2 > asked, "{name}: the grid answered {answered} of {asked}");
            }
        }
    }

    #[test]
    fn rounding_at_a_cell_boundary_does_not_hide_the_nearest_point() {
        // Bounding box [−1, 1]³ of 8 points: one unit per cell, a boundary at x = 0. The query and both candidates
        // sit within 4e-16 of it, where p − lo and q − lo round to either side of the boundary.
        let mut to = vec![[3.2e-16, 0.5, 0.5], [-6e-17, 0.5, 0.5]];
        to.extend([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, 1.0]]);
        to.extend([[-1.0, -1.0, 1.0], [1.0, 1.0, -1.0]]);
        let p = [1.2e-16, 0.5, 0.5];
        assert!(dist2(&p, &to[1]) < dist2(&p, &to[0]));
        assert_eq!(CellGrid::new(&to).nearest_below(&p, dist2(&p, &to[0]), 0), Some(1));
    }

    #[test]
    fn one_outlying_vertex_sends_the_crowded_cells_to_the_tree() {
        // The outlier stretches the bounding box so that the other 1,000 points share one cell: scanning it for
        // every query would be quadratic, so the grid declines and the k-d tree answers.
        let mut g = Gen(13);
        let mut to = g.points(1000, [1.0; 3]);
        to.push([1e4, 0.0, 0.0]);
        let grid = CellGrid::new(&to);
        let p = to[5].map(|c| c + 1e-3);
        assert_eq!(grid.nearest_below(&p, dist2(&p, &to[5]), 5), None);
        let from: Vec<[f32; 3]> = to.iter().map(|q| q.map(|c| c + g.unit() * 1e-3)).collect();
        let expected = brute_mean(&from, &to);
        let got = mean_nearest(&from, &to, true).expect("finite sets");
        assert!((got - expected).abs() <= 1e-6 * expected, "{got} vs {expected}");
    }

    #[test]
    fn the_unpaired_search_needs_no_index_correspondence() {
        let mut g = Gen(3);
        let to = g.points(400, [1.0; 3]);
        let from = g.points(250, [1.2; 3]);
        let expected = brute_mean(&from, &to);
        let got = mean_nearest(&from, &to, false).expect("finite sets");
        assert!((got - expected).abs() <= 1e-6 * expected, "{got} vs {expected}");
    }

    #[test]
    fn underflowing_squares_stay_within_the_stated_absolute_error() {
        // At 1e-25 every squared difference underflows f32 to 0 or a subnormal, so neighbours are chosen among
        // near-ties. The documented 1e-18 bound is loose at this scale: what this guards against is a NaN, an
        // infinite distance or a panic from the zero distances and the grid's degenerate cells.
        let mut g = Gen(17);
        let to = g.points(300, [1e-25; 3]);
        let from: Vec<[f32; 3]> = to.iter().map(|q| q.map(|c| c + g.unit() * 1e-25)).collect();
        let expected = brute_mean(&from, &to);
        let got = mean_nearest(&from, &to, true).expect("finite sets");
        assert!(
            got.is_finite() && (got - expected).abs() <= 1e-18,
            "{got} vs {expected}"
        );
    }

    #[test]
    fn coordinates_whose_squares_overflow_f32_are_refused() {
        let near = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let far = [[1.0, 2.0, 3.0], [4.0, 5.0e19, 6.0]];
        for (from, to) in [(&near, &far), (&far, &near)] {
            for paired in [false, true] {
                let err = mean_nearest(from, to, paired).expect_err("refused").to_string();
                assert!(err.contains("5e19") && err.contains("overflow"), "{err}");
            }
        }
        assert!(mean_nearest(&near, &near, true).is_ok());
    }
}
