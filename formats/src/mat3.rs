//! 3-vector and 3 × 3 matrix helpers in f64 (row-major), shared by the ACAP features, the MD3 tag placement and the
//! scene metrics: products, the inverse, a Jacobi eigensolver for symmetric matrices, the rotation polar
//! decomposition, and the rotation log/exp maps.

pub type Vec3 = [f64; 3];
pub type Mat3 = [[f64; 3]; 3];

pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub fn add_scaled(a: Vec3, b: Vec3, s: f64) -> Vec3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// a · bᵀ scaled by `w`, added into `m`.
pub fn add_outer(m: &mut Mat3, w: f64, a: Vec3, b: Vec3) {
    for (row, &ai) in m.iter_mut().zip(&a) {
        for (x, &bj) in row.iter_mut().zip(&b) {
            *x += w * ai * bj;
        }
    }
}

pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

pub fn transpose(m: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

pub fn add_mat(a: &Mat3, b: &Mat3, s: f64) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + s * b[i][j]))
}

pub fn trace(m: &Mat3) -> f64 {
    m[0][0] + m[1][1] + m[2][2]
}

fn column(m: &Mat3, j: usize) -> Vec3 {
    [m[0][j], m[1][j], m[2][j]]
}

fn from_columns(c: [Vec3; 3]) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| c[j][i]))
}

/// The inverse by cofactors; `None` when the determinant is zero or not finite.
pub fn inverse(m: &Mat3) -> Option<Mat3> {
    let c0 = cross(m[1], m[2]);
    let c1 = cross(m[2], m[0]);
    let c2 = cross(m[0], m[1]);
    let det = dot(m[0], c0);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // Rows of the adjugate transposed: inverse = [c0 c1 c2] / det (as columns).
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| [c0, c1, c2][j][i] / det)
    }))
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations: eigenvalues in descending order and
/// the eigenvectors as the columns of a rotation (determinant +1).
pub fn symmetric_eigen(m: &Mat3) -> (Vec3, Mat3) {
    let mut a = *m;
    let mut v = IDENTITY;
    for _sweep in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let diag = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= f64::EPSILON * 1e-3 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a ← Jᵀ a J, v ← v J with J the rotation in the (p, q) plane.
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let values = order.map(|i| a[i][i]);
    let mut cols = order.map(|i| column(&v, i));
    if dot(cross(cols[0], cols[1]), cols[2]) < 0.0 {
        cols[2] = scale(cols[2], -1.0);
    }
    (values, from_columns(cols))
}

/// The unit vector along `a − (a·u) u`, or `None` when that is (numerically) zero.
fn orthonormal_to(a: Vec3, u: Vec3) -> Option<Vec3> {
    let w = add_scaled(a, u, -dot(a, u));
    let n = norm(w);
    (n > 1e-12 * norm(a).max(f64::MIN_POSITIVE)).then(|| scale(w, 1.0 / n))
}

/// Rotation polar decomposition `t = r · s`: `r` a rotation (det +1), `s` symmetric; when det t < 0 the
/// direction of the smallest singular value carries the sign in `s`. A rank-deficient `t` gets a deterministic
/// completion of the missing directions (Gram–Schmidt of the right singular vectors); `t = 0` gives `r = I`.
pub fn polar(t: &Mat3) -> (Mat3, Mat3) {
    let (lambda, v) = symmetric_eigen(&mat_mul(&transpose(t), t));
    let r = if lambda[0] <= 0.0 || !lambda[0].is_finite() {
        IDENTITY
    } else {
        let vc = [column(&v, 0), column(&v, 1), column(&v, 2)];
        let t1 = mat_vec(t, vc[0]);
        let u1 = scale(t1, 1.0 / norm(t1));
        let u2 = orthonormal_to(mat_vec(t, vc[1]), u1)
            .filter(|_| lambda[1] > 1e-24 * lambda[0])
            .or_else(|| orthonormal_to(vc[1], u1))
            .or_else(|| orthonormal_to(vc[2], u1))
            .unwrap_or_else(|| any_orthonormal(u1));
        let u3 = cross(u1, u2);
        mat_mul(&from_columns([u1, u2, u3]), &transpose(&v))
    };
    let rt_t = mat_mul(&transpose(&r), t);
    let s = std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (rt_t[i][j] + rt_t[j][i])));
    (r, s)
}

fn any_orthonormal(u: Vec3) -> Vec3 {
    let axis = if u[0].abs() <= u[1].abs() && u[0].abs() <= u[2].abs() {
        [1.0, 0.0, 0.0]
    } else if u[1].abs() <= u[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let c = cross(u, axis);
    scale(c, 1.0 / norm(c))
}

/// Unit axis and angle θ ∈ [0, π] of a rotation; the axis is zero when θ = 0.
pub fn log_map(r: &Mat3) -> (Vec3, f64) {
    let cos = (trace(r) - 1.0) / 2.0;
    let vee = [
        0.5 * (r[2][1] - r[1][2]),
        0.5 * (r[0][2] - r[2][0]),
        0.5 * (r[1][0] - r[0][1]),
    ];
    let sin = norm(vee);
    let theta = sin.atan2(cos);
    if cos >= 0.0 {
        if sin > 0.0 {
            (scale(vee, 1.0 / sin), theta)
        } else {
            ([0.0; 3], 0.0)
        }
    } else {
        // Near π the antisymmetric part vanishes: read the axis from (R + Rᵀ)/2 − cos θ·I = (1 − cos θ) ω ωᵀ.
        let sym: Mat3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| 0.5 * (r[i][j] + r[j][i]) - if i == j { cos } else { 0.0 })
        });
        let mut col = 0;
        for k in 1..3 {
            if sym[k][k] > sym[col][col] {
                col = k;
            }
        }
        let w = column(&sym, col);
        let w = scale(w, 1.0 / norm(w));
        let w = if dot(w, vee) < 0.0 { scale(w, -1.0) } else { w };
        (w, theta)
    }
}

/// Rotation of the rotation vector `rv` (Rodrigues).
pub fn exp_map(rv: Vec3) -> Mat3 {
    let theta = norm(rv);
    if theta == 0.0 {
        return IDENTITY;
    }
    let a = scale(rv, 1.0 / theta);
    let k: Mat3 = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
    let k2 = mat_mul(&k, &k);
    add_mat(&add_mat(&IDENTITY, &k, theta.sin()), &k2, 1.0 - theta.cos())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    fn det(m: &Mat3) -> f64 {
        dot(m[0], cross(m[1], m[2]))
    }

    #[test]
    fn eigen_reconstructs_and_sorts() {
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, -0.2], [0.5, -0.2, 1.0]];
        let (l, v) = symmetric_eigen(&m);
        assert!(l[0] >= l[1] && l[1] >= l[2]);
        let d: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| if i == j { l[i] } else { 0.0 }));
        assert!(close(&mat_mul(&mat_mul(&v, &d), &transpose(&v)), &m, 1e-12));
        assert!((det(&v) - 1.0).abs() < 1e-12);
        assert!((l.iter().sum::<f64>() - 8.0).abs() < 1e-12);
    }

    #[test]
    fn polar_of_rotation_times_stretch() {
        let r0 = exp_map([0.3, -1.2, 0.7]);
        let s0 = [[1.5, 0.2, 0.0], [0.2, 0.8, 0.1], [0.0, 0.1, 1.1]];
        let (r, s) = polar(&mat_mul(&r0, &s0));
        assert!(close(&r, &r0, 1e-12), "{r:?}");
        assert!(close(&s, &s0, 1e-12), "{s:?}");
        // A reflection: r stays a rotation, s takes the sign, t = r s still holds.
        let t = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -0.5]];
        let (r, s) = polar(&t);
        assert!((det(&r) - 1.0).abs() < 1e-12);
        assert!(close(&mat_mul(&r, &s), &t, 1e-12));
        // Rank one and zero: still a rotation, no NaN.
        let t = [[1.0, 2.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let (r, s) = polar(&t);
        assert!((det(&r) - 1.0).abs() < 1e-12 && close(&mat_mul(&r, &s), &t, 1e-12));
        assert_eq!(polar(&[[0.0; 3]; 3]).0, IDENTITY);
    }

    #[test]
    fn log_inverts_exp_including_near_pi() {
        for rv in [
            [0.0, 0.0, 1e-9],
            [0.4, -0.1, 0.2],
            [0.0, 3.0, 0.0],
            [std::f64::consts::PI, 0.0, 0.0],
        ] {
            let (axis, theta) = log_map(&exp_map(rv));
            let back = scale(axis, theta);
            assert!(close(&exp_map(back), &exp_map(rv), 1e-12), "{rv:?} -> {back:?}");
            assert!((theta - norm(rv)).abs() < 1e-9, "{rv:?}: θ {theta}");
        }
        assert_eq!(log_map(&IDENTITY), ([0.0; 3], 0.0));
    }

    #[test]
    fn inverse_and_singular() {
        let m = [[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]];
        assert!(close(&mat_mul(&m, &inverse(&m).unwrap()), &IDENTITY, 1e-12));
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }
}
