//! Point queries against a scene (docs/method.md §6.5): the generalized winding number (inside when above ½, exactly
//! 1 inside a closed outward-wound part and 0 outside, robust to small gaps), the exact nearest surface point, and
//! the signed distance. Each visits every triangle: O(M) per query.

use super::Scene;
use crate::mat3::{add_scaled, cross, dot, norm, sub};

/// Winding number of `p` with respect to `scene` ((E8)): ≈ 1 inside a closed outward-wound part, ≈ 0 outside.
pub fn winding_number(scene: &Scene, p: [f64; 3]) -> f64 {
    let mut total = 0.0;
    for f in &scene.faces {
        let [a, b, c] = f.map(|v| sub(scene.vertices[v as usize].map(f64::from), p));
        let (la, lb, lc) = (norm(a), norm(b), norm(c));
        let num = dot(a, cross(b, c));
        let den = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}

/// The point of `scene`'s surface nearest to `p` (the first of equally near ones); `p` itself for a scene without
/// triangles, which [`Scene::new`] refuses.
pub fn nearest_point(scene: &Scene, p: [f64; 3]) -> [f64; 3] {
    let mut best = (f64::INFINITY, p);
    for f in &scene.faces {
        let [a, b, c] = f.map(|v| scene.vertices[v as usize].map(f64::from));
        let q = closest_on_triangle(p, a, b, c);
        let d = norm(sub(p, q));
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}

/// Distance from `p` to the nearest triangle of `scene` ((E9)); infinite for a scene without triangles.
pub fn surface_distance(scene: &Scene, p: [f64; 3]) -> f64 {
    scene
        .faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| scene.vertices[v as usize].map(f64::from));
            norm(sub(p, closest_on_triangle(p, a, b, c)))
        })
        .fold(f64::INFINITY, f64::min)
}

/// Signed distance to the scene's surface: negative inside ((E8)–(E9)).
pub fn signed_distance(scene: &Scene, p: [f64; 3]) -> f64 {
    let d = surface_distance(scene, p);
    if winding_number(scene, p) > 0.5 { -d } else { d }
}

/// The point of triangle `abc` nearest to `p` (Ericson, Real-Time Collision Detection, §5.1.5).
fn closest_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return add_scaled(a, ab, d1 / (d1 - d3));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return add_scaled(a, ac, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return add_scaled(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        // A degenerate (zero-area) triangle whose edges were all passed: its nearest vertex.
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| norm(sub(p, *x)).total_cmp(&norm(sub(p, *y))))
            .unwrap_or(a);
    }
    let (v, w) = (vb / denom, vc / denom);
    add_scaled(add_scaled(a, ab, v), ac, w)
}
