//! ACAP deformation features of a fixed-topology mesh sequence (the representation of the faithful BD-LSTM
//! baseline, after Gao et al.'s as-consistent-as-possible representation) and the reconstruction of vertex
//! positions from them by sparse least squares.
//!
//! Definitions (the independent reference `scripts/acap_reference.py` implements the same ones):
//!
//! - **Edge weights.** For each triangle of the reference mesh and each corner c opposite the edge (i, j),
//!   ½ cot(angle at c) = ½ (u·v)/|u × v| with u = q_i − q_c, v = q_j − q_c is added to c_ij. Degenerate triangles
//!   (|(b − a) × (c − a)| ≤ [`DEGENERATE_AREA`] · longest edge², or a repeated vertex index) add nothing, but
//!   their edges stay in the graph. Every weight is then clamped to [[`WEIGHT_MIN`], [`WEIGHT_MAX`]], so the
//!   Laplacian of the graph is positive semi-definite and connected where the mesh is.
//! - **Bridges.** A mesh of several connected components (separate limbs, an isolated vertex) gets bridge edges
//!   between its closest vertex pairs (Borůvka; weight [`WEIGHT_MIN`] · min(1, h̄²/d²), h̄ the mean edge length),
//!   so the features also carry how the parts move relative to each other and the graph is connected.
//! - **Deformation gradient** of vertex i in frame p against the reference q (one-ring least squares,
//!   e_ij = q_i − q_j, e'_ij = p_i − p_j):
//!   T_i = argmin Σ_j c_ij ‖e'_ij − T e_ij‖² + λ_i ‖T − K_i‖²  =  (B_i + λ_i K_i)(A_i + λ_i I)⁻¹,
//!   A_i = Σ_j c_ij e_ij e_ijᵀ, B_i = Σ_j c_ij e'_ij e_ijᵀ, λ_i = [`TIKHONOV`] · tr(A_i)/3, and K_i the rotation
//!   that best aligns the ring (the rotation factor of B_i). The small pull towards K_i only decides directions
//!   the ring does not span (a planar or collinear one-ring), so a rigid motion gives T_i = R exactly there too.
//!   **Fallback:** a vertex with tr(A_i) = 0 (all its neighbours on top of it, or a one-vertex mesh) gets T_i = I.
//! - **Polar decomposition** T_i = R_i S_i, R_i a rotation, S_i symmetric (for det T_i < 0 the sign sits in S_i).
//! - **Rotation vectors, as consistent as possible.** Each R_i is an axis ω and angle θ ∈ [0, π]; every
//!   r_i = θω + 2πkω (k ∈ ℤ, which covers the flipped axis too) is the same rotation. Per connected component of
//!   the edge graph the seed (its smallest vertex index) takes the candidate closest to its value in the
//!   previous frame of the sequence (zero before the first frame); then a breadth-first walk in ascending
//!   neighbour order gives each newly reached vertex the candidate closest to the mean of its already assigned
//!   neighbours: k = ⌊ω·(m − θω)/(2π) + ½⌋ (a zero axis takes the direction of m). A field whose angle reaches
//!   2π (where the axis is undefined) can still jump between neighbours.
//! - **Feature** (9 channels, [`ACAP_CHANNELS`]): r_x, r_y, r_z, S_00, S_01, S_02, S_11, S_12, S_22; scaled to
//!   [−0.95, 0.95] by [`AcapScaling`].
//! - **Reconstruction** ([`Reconstruction`]) solves a sparse least-squares problem for the positions (normal
//!   equations factorised once per topology with a sparse Cholesky, never a dense N × N system). The default
//!   fits the weighted one-ring moments B_i(p) = Σ_j c_ij (p_i − p_j) e_ijᵀ, which the features determine exactly
//!   (B_i = T_i(A_i + λ_i I) − λ_i K_i), so the round trip is exact for any deformation; Gao et al.'s ARAP-style
//!   system Σ c_ij ‖(p_i − p_j) − ½(T_i + T_j) e_ij‖² is the alternative, exact only for deformations that are
//!   affine on every one-ring. Features do not see translations: the smallest vertex is pinned while solving and
//!   the result is moved so that its centroid equals the reference centroid.

mod reconstruct;
mod scaling;

use rayon::prelude::*;

pub use reconstruct::Reconstruction;
pub use scaling::{AcapScaling, ScalingGranularity};

use crate::error::{DataError, Result};
use crate::mat3::{self, Mat3, Vec3};

/// Channels of one vertex's feature: rotation vector (3) and the upper triangle of S (6).
pub const ACAP_CHANNELS: usize = 9;
/// Smallest cotangent edge weight after clamping (dimensionless).
pub const WEIGHT_MIN: f64 = 1e-2;
/// Largest cotangent edge weight after clamping (dimensionless).
pub const WEIGHT_MAX: f64 = 1e2;
/// A triangle with |cross| ≤ this · (longest edge)² gives no cotangent weights.
pub const DEGENERATE_AREA: f64 = 1e-12;
/// Relative weight λ_i / (tr A_i / 3) of the pull towards the ring's best rotation.
pub const TIKHONOV: f64 = 1e-6;

/// Clear error unless `clip` has the fixed topology of `n` vertices and `faces` that the clip `name` has (what the
/// ACAP features of one reference mesh need).
pub fn check_topology(name: &str, n: usize, faces: &[[u32; 3]], clip: &crate::Clip) -> Result<()> {
    if clip.n_vertices != n || clip.faces != faces {
        return Err(DataError::new(
            &clip.id,
            "faces",
            format!(
                "ACAP features need one fixed topology: this clip has {} vertices and {} triangles, {name} has {n} \
                 and {} (a single-topology store: `any4d data synth --body FAMILY`)",
                clip.n_vertices,
                clip.faces.len(),
                faces.len()
            ),
        ));
    }
    Ok(())
}

/// The features of one frame: `[N]` rows of [`ACAP_CHANNELS`] values.
pub type AcapFrame = Vec<[f32; ACAP_CHANNELS]>;

/// Everything that depends only on the reference mesh: the weighted one-ring graph, the per-vertex normal
/// matrices, the connected components and the factorised Laplacian.
pub struct AcapTopology {
    source: String,
    reference: Vec<Vec3>,
    /// Sorted adjacency (CSR): neighbours of v are `nbr[nbr_ptr[v]..nbr_ptr[v + 1]]`, ascending.
    nbr_ptr: Vec<usize>,
    nbr: Vec<u32>,
    nbr_weight: Vec<f64>,
    /// Per-vertex normal matrices; `None` for the identity fallback (tr A_i = 0).
    local: Vec<Option<LocalFrame>>,
    component: Vec<usize>,
    seeds: Vec<usize>,
    component_size: Vec<usize>,
    ref_centroid: Vec<Vec3>,
    solvers: reconstruct::Solvers,
    bridges: usize,
}

/// What vertex i's least squares needs from the reference: A_i + λ_i I, its inverse, λ_i and tr A_i.
struct LocalFrame {
    a_reg: Mat3,
    inverse: Mat3,
    lambda: f64,
    trace: f64,
}

impl std::fmt::Debug for AcapTopology {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AcapTopology")
            .field("source", &self.source)
            .field("vertices", &self.reference.len())
            .field("edges", &(self.nbr.len() / 2))
            .field("components", &self.seeds.len())
            .finish()
    }
}

fn to_f64(p: [f32; 3]) -> Vec3 {
    p.map(f64::from)
}

/// Undirected edges `(i, j)`, i < j, ascending, with their clamped cotangent weights.
fn edge_weights(q: &[Vec3], faces: &[[u32; 3]]) -> Vec<(u32, u32, f64)> {
    let mut half: Vec<(u32, u32, f64)> = Vec::with_capacity(faces.len() * 3);
    for f in faces {
        let [a, b, c] = f.map(|v| q[v as usize]);
        let cross = mat3::norm(mat3::cross(mat3::sub(b, a), mat3::sub(c, a)));
        let longest = [mat3::sub(b, a), mat3::sub(c, b), mat3::sub(a, c)]
            .map(|e| mat3::dot(e, e))
            .into_iter()
            .fold(0.0, f64::max);
        let distinct = f[0] != f[1] && f[1] != f[2] && f[0] != f[2];
        let good = distinct && longest > 0.0 && cross > DEGENERATE_AREA * longest;
        for k in 0..3 {
            let (i, j, c) = (f[(k + 1) % 3], f[(k + 2) % 3], f[k]);
            if i == j {
                continue;
            }
            let cot = if good {
                let (u, v) = (
                    mat3::sub(q[i as usize], q[c as usize]),
                    mat3::sub(q[j as usize], q[c as usize]),
                );
                mat3::dot(u, v) / cross
            } else {
                0.0
            };
            half.push((i.min(j), i.max(j), 0.5 * cot));
        }
    }
    half.sort_unstable_by_key(|&(i, j, _)| (i, j));
    let mut edges: Vec<(u32, u32, f64)> = Vec::with_capacity(half.len() / 2 + 1);
    for (i, j, w) in half {
        match edges.last_mut() {
            Some(last) if (last.0, last.1) == (i, j) => last.2 += w,
            _ => edges.push((i, j, w)),
        }
    }
    for e in &mut edges {
        e.2 = e.2.clamp(WEIGHT_MIN, WEIGHT_MAX);
    }
    edges
}

fn find(parent: &mut [usize], v: usize) -> usize {
    let mut root = v;
    while parent[root] != root {
        root = parent[root];
    }
    let mut v = v;
    while parent[v] != root {
        (parent[v], v) = (root, parent[v]);
    }
    root
}

/// Joins the connected components of `edges` into one (Borůvka): every round, each component takes its closest
/// vertex pair to another component (by squared distance, then the smaller, then the larger index), and those
/// pairs become bridge edges of weight [`WEIGHT_MIN`] · min(1, h̄² / d²), h̄ the mean mesh edge length. Returns the
/// number of bridges; `edges` stays sorted.
fn add_bridges(q: &[Vec3], edges: &mut Vec<(u32, u32, f64)>) -> usize {
    let n = q.len();
    let mut parent: Vec<usize> = (0..n).collect();
    for &(i, j, _) in edges.iter() {
        let (a, b) = (find(&mut parent, i as usize), find(&mut parent, j as usize));
        parent[a.max(b)] = a.min(b);
    }
    let lengths: Vec<f64> = edges
        .iter()
        .map(|&(i, j, _)| mat3::norm(mat3::sub(q[i as usize], q[j as usize])))
        .collect();
    let mean_length = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
    let mut bridges = Vec::new();
    loop {
        let roots: Vec<usize> = (0..n).map(|v| find(&mut parent, v)).collect();
        if roots.iter().all(|&r| r == roots[0]) {
            break;
        }
        // The closest vertex of another component for every vertex (the first on ties: the smallest index).
        let nearest: Vec<(f64, usize)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let mut best = (f64::INFINITY, usize::MAX);
                for (j, qj) in q.iter().enumerate() {
                    if roots[j] != roots[i] {
                        let d = mat3::sub(q[i], *qj);
                        let d2 = mat3::dot(d, d);
                        if d2 < best.0 {
                            best = (d2, j);
                        }
                    }
                }
                best
            })
            .collect();
        let mut per_root: std::collections::BTreeMap<usize, (f64, usize, usize)> = Default::default();
        for (i, &(d2, j)) in nearest.iter().enumerate() {
            let key = (d2, i.min(j), i.max(j));
            let slot = per_root.entry(roots[i]).or_insert(key);
            if key.0 < slot.0 || (key.0 == slot.0 && (key.1, key.2) < (slot.1, slot.2)) {
                *slot = key;
            }
        }
        let mut chosen: Vec<(f64, usize, usize)> = per_root.into_values().collect();
        chosen.sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        for (d2, a, b) in chosen {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
                let w = if d2 > 0.0 {
                    WEIGHT_MIN * (mean_length * mean_length / d2).min(1.0)
                } else {
                    WEIGHT_MIN
                };
                bridges.push((a as u32, b as u32, w));
            }
        }
    }
    let count = bridges.len();
    edges.extend(bridges);
    edges.sort_unstable_by_key(|&(i, j, _)| (i, j));
    count
}

impl AcapTopology {
    /// Builds the topology of a mesh whose reference frame is `reference`; `source` names the clip in errors.
    ///
    /// # Errors
    /// Fewer than one vertex, a non-finite reference coordinate, a face indexing past the vertices, or a failed
    /// factorisation (which positive clamped weights and pinned components rule out).
    ///
    /// # Shapes
    /// - `reference`: `[N]` xyz; `faces`: `[M]` triangles
    pub fn new(source: &str, reference: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<Self> {
        let err = |field: &str, reason: String| DataError::new(source, field, reason);
        let n = reference.len();
        if n == 0 {
            return Err(err("vertices", "the reference frame has no vertices".into()));
        }
        if let Some(v) = reference.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(err(
                "vertices",
                format!("non-finite reference coordinate at vertex {v}"),
            ));
        }
        if let Some((i, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= n))
        {
            return Err(err("faces", format!("face {i} = {f:?} indexes past the {n} vertices")));
        }
        let q: Vec<Vec3> = reference.iter().copied().map(to_f64).collect();
        let mut edges = edge_weights(&q, faces);
        let bridges = add_bridges(&q, &mut edges);

        let mut degree = vec![0usize; n];
        for &(i, j, _) in &edges {
            degree[i as usize] += 1;
            degree[j as usize] += 1;
        }
        let mut nbr_ptr = vec![0usize; n + 1];
        for v in 0..n {
            nbr_ptr[v + 1] = nbr_ptr[v] + degree[v];
        }
        let mut fill = nbr_ptr.clone();
        let mut nbr = vec![0u32; nbr_ptr[n]];
        let mut nbr_weight = vec![0.0; nbr_ptr[n]];
        // Edges are sorted by (i, j): walking them fills every list in ascending order (j > i for the first
        // entry, i < j for the mirrored one, and all mirrored entries of v precede its own in the sort).
        let mut directed: Vec<(u32, u32, f64)> = edges.iter().flat_map(|&(i, j, w)| [(i, j, w), (j, i, w)]).collect();
        directed.sort_unstable_by_key(|&(i, j, _)| (i, j));
        for (i, j, w) in directed {
            let slot = &mut fill[i as usize];
            nbr[*slot] = j;
            nbr_weight[*slot] = w;
            *slot += 1;
        }

        let local = (0..n)
            .map(|i| {
                let mut a = [[0.0; 3]; 3];
                for k in nbr_ptr[i]..nbr_ptr[i + 1] {
                    let e = mat3::sub(q[i], q[nbr[k] as usize]);
                    mat3::add_outer(&mut a, nbr_weight[k], e, e);
                }
                let trace = mat3::trace(&a);
                if trace <= 0.0 {
                    return None;
                }
                let lambda = TIKHONOV * trace / 3.0;
                let a_reg = mat3::add_mat(&a, &mat3::IDENTITY, lambda);
                mat3::inverse(&a_reg).map(|inverse| LocalFrame {
                    a_reg,
                    inverse,
                    lambda,
                    trace,
                })
            })
            .collect();

        let mut topo = Self {
            source: source.to_string(),
            reference: q,
            nbr_ptr,
            nbr,
            nbr_weight,
            local,
            component: vec![usize::MAX; n],
            seeds: Vec::new(),
            component_size: Vec::new(),
            ref_centroid: Vec::new(),
            solvers: reconstruct::Solvers::default(),
            bridges,
        };
        topo.find_components();
        topo.solvers = topo.factorise()?;
        Ok(topo)
    }

    /// Number of vertices N.
    pub fn vertices(&self) -> usize {
        self.reference.len()
    }

    /// Number of connected components of the edge graph after bridging (1 for any mesh with a vertex).
    pub fn components(&self) -> usize {
        self.seeds.len()
    }

    /// Number of bridge edges added between the mesh's connected components.
    pub fn bridges(&self) -> usize {
        self.bridges
    }

    /// The one-ring neighbours of `v`, ascending.
    pub fn neighbours(&self, v: usize) -> &[u32] {
        &self.nbr[self.nbr_ptr[v]..self.nbr_ptr[v + 1]]
    }

    /// The undirected edges `[a, b]`, a < b, ascending (the graph the features and the mesh convolution use).
    pub fn edges(&self) -> Vec<[u32; 2]> {
        (0..self.vertices())
            .flat_map(|v| {
                self.neighbours(v)
                    .iter()
                    .filter(move |&&u| u as usize > v)
                    .map(move |&u| [v as u32, u])
            })
            .collect()
    }

    /// Components by breadth-first search from the smallest unvisited vertex; the same walk order as the
    /// rotation consistency.
    fn find_components(&mut self) {
        let n = self.vertices();
        let mut queue = std::collections::VecDeque::new();
        for s in 0..n {
            if self.component[s] != usize::MAX {
                continue;
            }
            let cid = self.seeds.len();
            self.seeds.push(s);
            self.component[s] = cid;
            queue.push_back(s);
            while let Some(v) = queue.pop_front() {
                for &u in &self.nbr[self.nbr_ptr[v]..self.nbr_ptr[v + 1]] {
                    if self.component[u as usize] == usize::MAX {
                        self.component[u as usize] = cid;
                        queue.push_back(u as usize);
                    }
                }
            }
        }
        self.component_size = vec![0; self.seeds.len()];
        self.ref_centroid = vec![[0.0; 3]; self.seeds.len()];
        for (v, &c) in self.component.iter().enumerate() {
            self.component_size[c] += 1;
            self.ref_centroid[c] = mat3::add_scaled(self.ref_centroid[c], self.reference[v], 1.0);
        }
        for (c, size) in self.ref_centroid.iter_mut().zip(&self.component_size) {
            *c = mat3::scale(*c, 1.0 / *size as f64);
        }
    }

    fn check_frame(&self, f: usize, frame: &[[f32; 3]]) -> Result<()> {
        if frame.len() != self.vertices() {
            return Err(DataError::new(
                &self.source,
                "vertices",
                format!(
                    "frame {f} has {} vertices, the reference {}",
                    frame.len(),
                    self.vertices()
                ),
            ));
        }
        if let Some(v) = frame.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(DataError::new(
                &self.source,
                "vertices",
                format!("non-finite coordinate at frame {f}, vertex {v}"),
            ));
        }
        Ok(())
    }

    /// Deformation gradients T_i of one frame against the reference.
    fn gradients(&self, frame: &[[f32; 3]]) -> Vec<Mat3> {
        let p: Vec<Vec3> = frame.iter().copied().map(to_f64).collect();
        (0..self.vertices())
            .map(|i| {
                let Some(local) = &self.local[i] else {
                    return mat3::IDENTITY;
                };
                let mut b = [[0.0; 3]; 3];
                for k in self.nbr_ptr[i]..self.nbr_ptr[i + 1] {
                    let j = self.nbr[k] as usize;
                    let (e, e1) = (mat3::sub(self.reference[i], self.reference[j]), mat3::sub(p[i], p[j]));
                    mat3::add_outer(&mut b, self.nbr_weight[k], e1, e);
                }
                let (kabsch, _) = mat3::polar(&b);
                mat3::mat_mul(&mat3::add_mat(&b, &kabsch, local.lambda), &local.inverse)
            })
            .collect()
    }

    /// ACAP features of a sequence of frames (rotation choices carried from each frame to the next).
    ///
    /// # Errors
    /// A frame with another vertex count than the reference, or a non-finite coordinate.
    ///
    /// # Shapes
    /// - `frames`: `[T]` frames of `[N]` xyz; returns `[T]` frames of `[N]` × [`ACAP_CHANNELS`]
    pub fn features(&self, frames: &[&[[f32; 3]]]) -> Result<Vec<AcapFrame>> {
        for (f, frame) in frames.iter().enumerate() {
            self.check_frame(f, frame)?;
        }
        // Gradients, polar factors and canonical axis-angles are independent per frame; the consistent choice
        // of representatives walks the frames in order.
        let local: Vec<Vec<(Vec3, f64, Mat3)>> = frames
            .par_iter()
            .map(|frame| {
                self.gradients(frame)
                    .iter()
                    .map(|t| {
                        let (r, s) = mat3::polar(t);
                        let (axis, theta) = mat3::log_map(&r);
                        (axis, theta, s)
                    })
                    .collect()
            })
            .collect();
        let mut previous = vec![[0.0; 3]; self.seeds.len()];
        let mut out = Vec::with_capacity(frames.len());
        for frame in &local {
            let rv = self.consistent_rotations(frame, &previous);
            previous = self.seeds.iter().map(|&s| rv[s]).collect();
            out.push(
                rv.iter()
                    .zip(frame)
                    .map(|(r, (_, _, s))| {
                        [r[0], r[1], r[2], s[0][0], s[0][1], s[0][2], s[1][1], s[1][2], s[2][2]].map(|x| x as f32)
                    })
                    .collect(),
            );
        }
        Ok(out)
    }

    /// As-consistent-as-possible rotation vectors of one frame (see the module documentation).
    fn consistent_rotations(&self, local: &[(Vec3, f64, Mat3)], seed_targets: &[Vec3]) -> Vec<Vec3> {
        let n = self.vertices();
        let mut out = vec![[0.0; 3]; n];
        let mut done = vec![false; n];
        let mut queue = std::collections::VecDeque::new();
        for (&s, &target) in self.seeds.iter().zip(seed_targets) {
            out[s] = choose(local[s].0, local[s].1, target);
            done[s] = true;
            queue.push_back(s);
            while let Some(v) = queue.pop_front() {
                for &u in self.neighbours(v) {
                    let u = u as usize;
                    if done[u] {
                        continue;
                    }
                    let (mut sum, mut count) = ([0.0; 3], 0usize);
                    for &m in self.neighbours(u) {
                        if done[m as usize] {
                            sum = mat3::add_scaled(sum, out[m as usize], 1.0);
                            count += 1;
                        }
                    }
                    out[u] = choose(local[u].0, local[u].1, mat3::scale(sum, 1.0 / count as f64));
                    done[u] = true;
                    queue.push_back(u);
                }
            }
        }
        out
    }
}

/// The representative θω + 2πkω closest to `target` (a zero axis takes the target's direction).
fn choose(axis: Vec3, theta: f64, target: Vec3) -> Vec3 {
    let tau = 2.0 * std::f64::consts::PI;
    let axis = if axis == [0.0; 3] {
        let tn = mat3::norm(target);
        if tn == 0.0 {
            return [0.0; 3];
        }
        mat3::scale(target, 1.0 / tn)
    } else {
        axis
    };
    let r0 = mat3::scale(axis, theta);
    let k = (mat3::dot(axis, mat3::sub(target, r0)) / tau + 0.5).floor();
    mat3::add_scaled(r0, axis, tau * k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn choose_picks_the_nearest_cycle_and_sign() {
        let pi = std::f64::consts::PI;
        // 3 rad about +y is also −(2π − 3) about +y; near a target of 3.1 the first, near −3.2 the second.
        assert!((choose([0.0, 1.0, 0.0], 3.0, [0.0, 3.1, 0.0])[1] - 3.0).abs() < 1e-12);
        assert!((choose([0.0, 1.0, 0.0], 3.0, [0.0, -3.2, 0.0])[1] - (3.0 - 2.0 * pi)).abs() < 1e-12);
        assert!((choose([0.0, 1.0, 0.0], 0.5, [0.0, 13.0, 0.0])[1] - (0.5 + 4.0 * pi)).abs() < 1e-12);
        // A zero rotation next to a 2π one becomes 2π about the neighbour's axis.
        assert!((choose([0.0; 3], 0.0, [2.0 * pi - 0.1, 0.0, 0.0])[0] - 2.0 * pi).abs() < 1e-12);
        assert_eq!(choose([0.0; 3], 0.0, [0.0; 3]), [0.0; 3]);
    }

    #[test]
    fn cotangent_weights_of_a_right_triangle_pair() {
        // Unit square split along (0, 2): the diagonal sees two right angles (cot 0 → clamped), the sides
        // each one 45° angle (½ cot 45° = ½).
        let q = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let e = edge_weights(&q, &[[0, 1, 2], [0, 2, 3]]);
        let w = |i, j| e.iter().find(|x| (x.0, x.1) == (i, j)).unwrap().2;
        assert!((w(0, 1) - 0.5).abs() < 1e-12 && (w(2, 3) - 0.5).abs() < 1e-12);
        assert_eq!(w(0, 2), WEIGHT_MIN);
        assert_eq!(e.len(), 5);
    }
}
