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
///
/// # Shapes
/// - `points`: `[N]` rows of xyz; returns `[P]` indices
pub fn farthest_point_sampling(points: &[[f32; 3]], p: usize) -> Vec<u32> {
    let n = points.len();
    if n == 0 || p == 0 {
        return Vec::new();
    }
    let take = p.min(n);
    let xs: Vec<f32> = points.iter().map(|q| q[0]).collect();
    let ys: Vec<f32> = points.iter().map(|q| q[1]).collect();
    let zs: Vec<f32> = points.iter().map(|q| q[2]).collect();
    // Squared distance to the chosen set; chosen points hold −1 so they never win again.
    let mut dist = vec![f32::INFINITY; n];
    let mut out = Vec::with_capacity(p);
    let mut cur = 0usize;
    for _ in 0..take {
        out.push(cur as u32);
        dist[cur] = -1.0;
        let (cx, cy, cz) = (xs[cur], ys[cur], zs[cur]);
        let mut best = 0usize;
        let mut best_d = f32::NEG_INFINITY;
        for i in 0..n {
            let (dx, dy, dz) = (xs[i] - cx, ys[i] - cy, zs[i] - cz);
            let d = dist[i].min(dx * dx + dy * dy + dz * dz);
            dist[i] = d;
            // Strictly greater: the lowest index wins a tie.
            if d > best_d {
                best_d = d;
                best = i;
            }
        }
        cur = best;
    }
    for k in take..p {
        out.push(out[k % n]);
    }
    out
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
