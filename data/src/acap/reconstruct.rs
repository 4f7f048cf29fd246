//! Vertex positions from ACAP features by sparse least squares: the two normal-equation systems (factorised
//! once per topology with faer's sparse Cholesky) and the per-frame solve.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

use super::{ACAP_CHANNELS, AcapTopology};
use crate::error::{DataError, Result};
use crate::mat3::{self, Mat3, Vec3};

/// Which least-squares problem turns features back into positions (both pin one vertex per component and
/// centre each component on its reference centroid).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reconstruction {
    /// min Σ_i ‖B_i(p) − G_i‖²_F / tr(A_i) with B_i(p) = Σ_j c_ij (p_i − p_j) e_ijᵀ, the weighted one-ring moment
    /// of the positions, and G_i = T_i(A_i + λ_i I) − λ_i·rot(T_i(A_i + λ_i I)), which is exactly B_i when the
    /// features come from a mesh. B_i is linear in p, so the round trip is exact for any deformation. Default.
    RingMoments,
    /// Gao et al.'s ARAP-style system min Σ_(i,j) c_ij ‖(p_i − p_j) − ½(T_i + T_j) e_ij‖²: the graph Laplacian.
    /// Exact only for deformations that are affine on every one-ring; otherwise the one-ring fit leaves a
    /// residual (measured: 1e-5 to 9e-4 relative on bent and twisted 4096-vertex tubes).
    EdgePoisson,
}

/// The two factorised systems and the bookkeeping of pinned vertices.
#[derive(Default)]
pub(super) struct Solvers {
    /// Row of each vertex in the reduced (seeds removed) systems; `usize::MAX` for seeds.
    free_row: Vec<usize>,
    rows: usize,
    moments: Option<Llt<usize, f64>>,
    poisson: Option<Llt<usize, f64>>,
}

/// Lower-triangle triplets with duplicates summed.
fn merged(mut entries: Vec<(usize, usize, f64)>) -> Vec<Triplet<usize, usize, f64>> {
    entries.sort_unstable_by_key(|&(r, c, _)| (c, r));
    let mut out: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(entries.len());
    for (r, c, v) in entries {
        match out.last_mut() {
            Some(t) if (t.row, t.col) == (r, c) => t.val += v,
            _ => out.push(Triplet::new(r, c, v)),
        }
    }
    out
}

fn factor(source: &str, rows: usize, entries: Vec<(usize, usize, f64)>, what: &str) -> Result<Llt<usize, f64>> {
    let fail = |e: String| DataError::new(source, "faces", format!("{what}: {e}"));
    let m = SparseColMat::<usize, f64>::try_new_from_triplets(rows, rows, &merged(entries))
        .map_err(|e| fail(format!("{e:?}")))?;
    m.sp_cholesky(Side::Lower).map_err(|e| fail(e.to_string()))
}

impl AcapTopology {
    /// The columns and vectors of vertex i's block of the moment operator: (M x)_i = Σ_c v_c x_c with
    /// v_i = s_i Σ_j c_ij e_ij and v_j = −s_i c_ij e_ij, s_i = 1/√tr(A_i). Empty for the identity fallback.
    fn moment_block(&self, i: usize) -> Vec<(usize, Vec3)> {
        let Some(local) = &self.local[i] else {
            return Vec::new();
        };
        let s = 1.0 / local.trace.sqrt();
        let mut own = [0.0; 3];
        let mut block = vec![(i, own)];
        for k in self.nbr_ptr[i]..self.nbr_ptr[i + 1] {
            let j = self.nbr[k] as usize;
            let e = mat3::sub(self.reference[i], self.reference[j]);
            own = mat3::add_scaled(own, e, s * self.nbr_weight[k]);
            block.push((j, mat3::scale(e, -s * self.nbr_weight[k])));
        }
        block[0].1 = own;
        block
    }

    /// Factorises both systems with every component's seed removed.
    pub(super) fn factorise(&self) -> Result<Solvers> {
        let n = self.vertices();
        let mut free_row = vec![usize::MAX; n];
        let mut rows = 0;
        for (v, slot) in free_row.iter_mut().enumerate() {
            if self.seeds[self.component[v]] != v {
                *slot = rows;
                rows += 1;
            }
        }
        if rows == 0 {
            return Ok(Solvers {
                free_row,
                rows,
                moments: None,
                poisson: None,
            });
        }
        let lower = |a: usize, b: usize| {
            let (ra, rb) = (free_row[a], free_row[b]);
            (ra != usize::MAX && rb != usize::MAX && ra >= rb).then_some((ra, rb))
        };
        let mut poisson = Vec::with_capacity(self.nbr.len() + rows);
        let mut moments = Vec::new();
        for i in 0..n {
            for k in self.nbr_ptr[i]..self.nbr_ptr[i + 1] {
                let (j, w) = (self.nbr[k] as usize, self.nbr_weight[k]);
                if let Some((r, c)) = lower(i, i) {
                    poisson.push((r, c, w));
                }
                if let Some((r, c)) = lower(i, j) {
                    poisson.push((r, c, -w));
                }
            }
            let block = self.moment_block(i);
            for &(a, va) in &block {
                for &(b, vb) in &block {
                    if let Some((r, c)) = lower(a, b) {
                        moments.push((r, c, mat3::dot(va, vb)));
                    }
                }
            }
        }
        Ok(Solvers {
            moments: Some(factor(
                &self.source,
                rows,
                moments,
                "factorising the ring-moment system",
            )?),
            poisson: Some(factor(&self.source, rows, poisson, "factorising the Laplacian")?),
            free_row,
            rows,
        })
    }

    /// Vertex positions from one frame of (unscaled) features with `method`, each connected component centred on
    /// its reference centroid.
    ///
    /// # Errors
    /// Another vertex count than the reference, or a non-finite feature.
    ///
    /// # Shapes
    /// - `features`: `[N]` × [`ACAP_CHANNELS`]; returns `[N]` xyz
    pub fn reconstruct(&self, features: &[[f32; ACAP_CHANNELS]], method: Reconstruction) -> Result<Vec<[f32; 3]>> {
        let n = self.vertices();
        if features.len() != n {
            return Err(DataError::new(
                &self.source,
                "features",
                format!("{} feature rows for {n} vertices", features.len()),
            ));
        }
        if let Some(v) = features.iter().position(|f| !f.iter().all(|c| c.is_finite())) {
            return Err(DataError::new(
                &self.source,
                "features",
                format!("non-finite feature at vertex {v}"),
            ));
        }
        let t: Vec<Mat3> = features
            .iter()
            .map(|f| {
                let f = f.map(f64::from);
                let s = [[f[3], f[4], f[5]], [f[4], f[6], f[7]], [f[5], f[7], f[8]]];
                mat3::mat_mul(&mat3::exp_map([f[0], f[1], f[2]]), &s)
            })
            .collect();
        let solvers = &self.solvers;
        let mut rhs = Mat::<f64>::zeros(solvers.rows, 3);
        let mut add = |v: usize, x: Vec3| {
            let r = solvers.free_row[v];
            if r != usize::MAX {
                for (c, &x) in x.iter().enumerate() {
                    rhs[(r, c)] += x;
                }
            }
        };
        let llt = match method {
            Reconstruction::RingMoments => {
                for (i, ti) in t.iter().enumerate() {
                    let Some(local) = &self.local[i] else { continue };
                    // G_i = T_i(A_i + λI) − λ·rot(T_i(A_i + λI)), rows r = coordinates.
                    let ta = mat3::mat_mul(ti, &local.a_reg);
                    let g = mat3::add_mat(&ta, &mat3::polar(&ta).0, -local.lambda);
                    let s = 1.0 / local.trace.sqrt();
                    for (col, v) in self.moment_block(i) {
                        add(col, mat3::scale(mat3::mat_vec(&g, v), s));
                    }
                }
                &solvers.moments
            }
            Reconstruction::EdgePoisson => {
                for i in 0..n {
                    for k in self.nbr_ptr[i]..self.nbr_ptr[i + 1] {
                        let j = self.nbr[k] as usize;
                        let e = mat3::sub(self.reference[i], self.reference[j]);
                        let te = mat3::add_scaled(mat3::mat_vec(&t[i], e), mat3::mat_vec(&t[j], e), 1.0);
                        add(i, mat3::scale(te, 0.5 * self.nbr_weight[k]));
                    }
                }
                &solvers.poisson
            }
        };
        let mut p = vec![[0.0; 3]; n];
        if let Some(llt) = llt {
            llt.solve_in_place(rhs.as_mut());
            for (v, pv) in p.iter_mut().enumerate() {
                let r = solvers.free_row[v];
                if r != usize::MAX {
                    *pv = [rhs[(r, 0)], rhs[(r, 1)], rhs[(r, 2)]];
                }
            }
        }
        let mut centroid = vec![[0.0; 3]; self.seeds.len()];
        for (v, &c) in self.component.iter().enumerate() {
            centroid[c] = mat3::add_scaled(centroid[c], p[v], 1.0 / self.component_size[c] as f64);
        }
        Ok(p.iter()
            .zip(&self.component)
            .map(|(x, &c)| mat3::add_scaled(*x, mat3::sub(self.ref_centroid[c], centroid[c]), 1.0).map(|v| v as f32))
            .collect())
    }
}
