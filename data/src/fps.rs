//! Farthest point sampling of the P latent tokens on the reference frame (docs/method.md §2.5).
//!
//! Squared Euclidean distance, start index 0, ties to the lowest index: deterministic, so the indices can be
//! cached in the dataset. O(N · P) time, O(N) memory, f32 structure-of-arrays for a cache-friendly inner loop.

use rayon::prelude::*;

/// Indices of `p` farthest points of `points`, starting with index 0.
///
/// Each step picks the point whose squared distance to the already chosen set is largest; ties go to the lowest
/// index. Chosen points are never chosen again, so for `p ≤ N` the indices are distinct even when points
/// coincide. If `p > N` (the vertex filter rules this out: N ≥ 512 = P) the result is all N indices in FPS order
/// followed by that same order repeated cyclically until it has `p` entries. `N = 0` gives an empty vector.
/// Indices are u32, so N must not exceed `u32::MAX`.
///
/// # Shapes
/// - `points`: `[N]` rows of xyz; returns `[P]` indices
pub fn farthest_point_sampling(points: &[[f32; 3]], p: usize) -> Vec<u32> {
    let n = points.len();
    if n == 0 || p == 0 {
        return Vec::new();
    }
    debug_assert!(u32::try_from(n).is_ok(), "{n} points: indices are u32");
    let take = p.min(n);
    let xs: Vec<f32> = points.iter().map(|q| q[0]).collect();
    let ys: Vec<f32> = points.iter().map(|q| q[1]).collect();
    let zs: Vec<f32> = points.iter().map(|q| q[2]).collect();
    // Squared distance to the chosen set; chosen points hold −1 so they never win again.
    let mut dist = vec![f32::INFINITY; n];
    let mut out = Vec::with_capacity(p);
    pulp::Arch::new().dispatch(Sample {
        xyz: [&xs, &ys, &zs],
        dist: &mut dist,
        take,
        out: &mut out,
    });
    for k in take..p {
        out.push(out[k % n]);
    }
    out
}

/// The sampling loop under pulp's runtime dispatch: inlined into a function compiled for the widest vector
/// instructions this CPU has (AVX-512 or AVX2, chosen at run time), where the binary's baseline x86-64 target
/// would give it 4-lane SSE. No fused multiply-add is formed (Rust does not contract), so the distances, and hence
/// the indices, are the same on every CPU.
struct Sample<'a> {
    xyz: [&'a [f32]; 3],
    dist: &'a mut [f32],
    take: usize,
    out: &'a mut Vec<u32>,
}

impl pulp::WithSimd for Sample<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let mut cur = 0usize;
        for _ in 0..self.take {
            self.out.push(cur as u32);
            self.dist[cur] = -1.0;
            let centre = self.xyz.map(|c| c[cur]);
            cur = update_and_argmax(self.xyz, self.dist, centre);
        }
    }
}

/// Lanes of the running arg-max in [`update_and_argmax`].
const LANES: usize = 16;

/// Lowers each `dist[i]` to the squared distance from point `i` to `centre` and returns the index of the largest,
/// the lowest index among equals. Each of [`LANES`] lanes keeps its own running maximum (a strict `>`: its lowest
/// index) over the points it sees; the lanes are then merged by value, then by index, and the remainder past the
/// last whole chunk (higher indices) scanned with a strict `>`: the same index as one scan, in a form the compiler
/// vectorises.
#[inline(always)]
fn update_and_argmax(xyz: [&[f32]; 3], dist: &mut [f32], centre: [f32; 3]) -> usize {
    let n = dist.len();
    let whole = n - n % LANES;
    let [xs, ys, zs] = xyz;
    let (mut lane_max, mut lane_arg) = ([f32::NEG_INFINITY; LANES], [0u32; LANES]);
    let chunks = xs[..whole]
        .chunks_exact(LANES)
        .zip(ys[..whole].chunks_exact(LANES))
        .zip(zs[..whole].chunks_exact(LANES))
        .zip(dist[..whole].chunks_exact_mut(LANES));
    for (chunk, (((x, y), z), d)) in chunks.enumerate() {
        for l in 0..LANES {
            let (dx, dy, dz) = (x[l] - centre[0], y[l] - centre[1], z[l] - centre[2]);
            let v = d[l].min(dx * dx + dy * dy + dz * dz);
            d[l] = v;
            let better = v > lane_max[l];
            lane_max[l] = if better { v } else { lane_max[l] };
            lane_arg[l] = if better {
                (chunk * LANES + l) as u32
            } else {
                lane_arg[l]
            };
        }
    }
    let (mut best, mut best_d) = (0usize, f32::NEG_INFINITY);
    for (&v, &i) in lane_max.iter().zip(&lane_arg) {
        let i = i as usize;
        if v > best_d || (v == best_d && i < best) {
            (best, best_d) = (i, v);
        }
    }
    for i in whole..n {
        let (dx, dy, dz) = (xs[i] - centre[0], ys[i] - centre[1], zs[i] - centre[2]);
        let v = dist[i].min(dx * dx + dy * dy + dz * dz);
        dist[i] = v;
        // Strictly greater: the lowest index wins a tie.
        if v > best_d {
            (best, best_d) = (i, v);
        }
    }
    best
}

/// [`farthest_point_sampling`] of many point sets in parallel (rayon), `p` indices each.
///
/// # Shapes
/// - `clips`: B sets of `[N_b]` rows of xyz; returns B vectors of `[P]` indices
pub fn fps_many(clips: &[&[[f32; 3]]], p: usize) -> Vec<Vec<u32>> {
    clips.par_iter().map(|pts| farthest_point_sampling(pts, p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, seed: u32) -> Vec<[f32; 3]> {
        // A small deterministic hash, enough for spread-out points.
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s % 10_000) as f32 / 10_000.0
        };
        (0..n).map(|_| [next(), next(), next()]).collect()
    }

    #[test]
    fn hand_case_on_a_line() {
        // Points on the x axis: 0, 1, 10, 4, 6. Start 0 → farthest 10 (idx 2) → then 4 or 6? d(4)=min(16,36)=16,
        // d(6)=min(36,16)=16: tie → lowest index 3. Then d: 1→1, 6→4 → idx 4.
        let pts: Vec<[f32; 3]> = [0.0, 1.0, 10.0, 4.0, 6.0].iter().map(|&x| [x, 0.0, 0.0]).collect();
        assert_eq!(farthest_point_sampling(&pts, 4), vec![0, 2, 3, 4]);
        assert_eq!(farthest_point_sampling(&pts, 5), vec![0, 2, 3, 4, 1]);
    }

    #[test]
    fn ties_go_to_the_lowest_index() {
        // Index 0 at the origin; 2, 3, 4 all at distance 1 (tie → 2); 1 is closer (0.5).
        let pts = vec![
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.5],
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        // From 2: d(3) = min(1, 4) = 1 ties d(4) = min(1, 2) = 1 → 3; then 4; the close point 1 comes last.
        assert_eq!(farthest_point_sampling(&pts, 5), vec![0, 2, 3, 4, 1]);
        // Coincident points: distinct indices anyway, lowest first.
        let same = vec![[0.5, 0.5, 0.5]; 4];
        assert_eq!(farthest_point_sampling(&same, 4), vec![0, 1, 2, 3]);
    }

    #[test]
    fn deterministic_distinct_and_starts_at_zero() {
        let pts = cloud(2000, 7);
        let a = farthest_point_sampling(&pts, 512);
        let b = farthest_point_sampling(&pts, 512);
        assert_eq!(a, b);
        assert_eq!(a[0], 0);
        let mut s = a.clone();
        s.sort_unstable();
        s.dedup();
        assert_eq!(s.len(), 512);
        // FPS spreads points: the minimum pairwise gap among the first 16 beats that of the first 16 points.
        let gap = |ix: &[u32]| {
            let mut m = f32::INFINITY;
            for i in 0..ix.len() {
                for j in 0..i {
                    let (p, q) = (pts[ix[i] as usize], pts[ix[j] as usize]);
                    m = m.min((0..3).map(|k| (p[k] - q[k]).powi(2)).sum());
                }
            }
            m
        };
        let first: Vec<u32> = (0..16).collect();
        assert!(gap(&a[..16]) > gap(&first));
    }

    /// The sampling as one plain scan (the definition above), to compare the laned arg-max with.
    fn one_scan(points: &[[f32; 3]], p: usize) -> Vec<u32> {
        let n = points.len();
        let mut dist = vec![f32::INFINITY; n];
        let (mut out, mut cur) = (Vec::new(), 0usize);
        for _ in 0..p.min(n) {
            out.push(cur as u32);
            dist[cur] = -1.0;
            let c = points[cur];
            let (mut best, mut best_d) = (0, f32::NEG_INFINITY);
            for (i, q) in points.iter().enumerate() {
                let (dx, dy, dz) = (q[0] - c[0], q[1] - c[1], q[2] - c[2]);
                dist[i] = dist[i].min(dx * dx + dy * dy + dz * dz);
                if dist[i] > best_d {
                    (best, best_d) = (i, dist[i]);
                }
            }
            cur = best;
        }
        out
    }

    #[test]
    fn the_laned_arg_max_picks_what_one_scan_picks() {
        // Sizes around the 16 lanes, points on a coarse lattice (many exact ties across lanes), and repeated points.
        for (n, seed) in [
            (1, 1),
            (15, 2),
            (16, 3),
            (17, 4),
            (33, 5),
            (100, 6),
            (1000, 7),
            (4099, 8),
        ] {
            let lattice: Vec<[f32; 3]> = cloud(n, seed).iter().map(|q| q.map(|x| (x * 4.0).floor())).collect();
            let mut repeated = cloud(n, seed + 100);
            for i in (0..n).step_by(3) {
                repeated[i] = repeated[0];
            }
            for pts in [cloud(n, seed), lattice, repeated] {
                let p = n.min(300);
                assert_eq!(farthest_point_sampling(&pts, p), one_scan(&pts, p), "n {n}");
            }
        }
    }

    #[test]
    fn more_tokens_than_points_repeat_the_order() {
        let pts: Vec<[f32; 3]> = [0.0, 1.0, 10.0].iter().map(|&x| [x, 0.0, 0.0]).collect();
        assert_eq!(farthest_point_sampling(&pts, 7), vec![0, 2, 1, 0, 2, 1, 0]);
        assert!(farthest_point_sampling(&[], 4).is_empty());
    }

    /// Timing: `cargo test -p any4d-data fps_speed -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn fps_speed() {
        let pts = cloud(4096, 3);
        let start = std::time::Instant::now();
        let reps = 20;
        for _ in 0..reps {
            assert_eq!(farthest_point_sampling(&pts, 512).len(), 512);
        }
        let ms = start.elapsed().as_secs_f64() * 1e3 / reps as f64;
        println!("fps_speed: N = 4096, P = 512: {ms:.2} ms per clip");
    }

    #[test]
    fn many_matches_single() {
        let (a, b) = (cloud(600, 1), cloud(900, 2));
        let many = fps_many(&[&a, &b], 64);
        assert_eq!(
            many,
            vec![farthest_point_sampling(&a, 64), farthest_point_sampling(&b, 64)]
        );
    }
}
