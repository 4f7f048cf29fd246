#!/usr/bin/env python3
"""Independent numpy + scipy reference for the ACAP deformation features of data/src/acap/ (BD-LSTM, faithful
variant): per-vertex deformation gradients from one-ring least squares against the reference frame, polar
decomposition, axis-angle rotations with the as-consistent-as-possible choice, and both sparse least-squares
reconstructions of vertex positions (ring moments, edge Poisson). The linear scaling to [-0.95, 0.95] is not here.

Written separately from the Rust code (vectorised numpy, np.linalg.svd for the polar decomposition, scipy's
SuperLU for the sparse solve) so that a test compares two implementations, not one. The definitions it follows
are stated once, in the module documentation of data/src/acap/mod.rs; the constants below must match it.

Input (JSON): {"faces": [[a, b, c], ...], "frames": [T][N][3]}; frame 0 is the reference mesh.

Modes:
  --features IN OUT       write {"features": [T][N][9], "ring_moments": [T][N][3], "edge_poisson": [T][N][3]}
                          (features and both reconstructions) for the clip in IN
  --bench IN [--repeat K] [--method ring_moments|edge_poisson]
                          time feature extraction (with the factorisations) + reconstruction of every frame of the
                          clip in IN (best of K); prints one JSON object {"vertices", "frames", "method",
                          "features_s", "reconstruction_s", "total_s"}. Run with OMP_NUM_THREADS=1 for one core.
"""

import argparse
import json
import sys
import time
from collections import deque

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

WEIGHT_MIN = 1e-2  # clamp of the cotangent edge weights (dimensionless)
WEIGHT_MAX = 1e2
DEGENERATE_AREA = 1e-12  # a triangle with |cross| <= this * (longest edge)^2 gives no cotangent weights
TIKHONOV = 1e-6  # lambda_i = TIKHONOV * trace(A_i) / 3, the weight of the pull towards the ring's best rotation
SCALE_BOUND = 0.95
MIN_HALF_RANGE = 1e-6


def edge_weights(ref, faces):
    """Undirected edges (i < j, sorted) and their clamped cotangent weights."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    corners = []
    for k in range(3):  # corner k is opposite the edge (i, j)
        i, j, c = faces[:, (k + 1) % 3], faces[:, (k + 2) % 3], faces[:, k]
        corners.append((i, j, c))
    a, b, c = (ref[faces[:, k]] for k in range(3))
    cross = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max(np.stack([np.sum((b - a) ** 2, 1), np.sum((c - b) ** 2, 1), np.sum((a - c) ** 2, 1)]), axis=0)
    good = (cross > DEGENERATE_AREA * longest) & (longest > 0)
    good &= (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    keys, vals = [], []
    for i, j, c in corners:
        u, v = ref[i] - ref[c], ref[j] - ref[c]
        cot = np.where(good, np.sum(u * v, 1) / np.where(good, cross, 1.0), 0.0)
        distinct = i != j
        lo, hi = np.minimum(i, j)[distinct], np.maximum(i, j)[distinct]
        keys.append(np.stack([lo, hi], 1))
        vals.append(0.5 * cot[distinct])
    keys, vals = np.concatenate(keys), np.concatenate(vals)
    edges, inverse = np.unique(keys, axis=0, return_inverse=True)
    weights = np.zeros(len(edges))
    np.add.at(weights, inverse.reshape(-1), vals)
    return edges, np.clip(weights, WEIGHT_MIN, WEIGHT_MAX)


def add_bridges(ref, edges, weights):
    """Borůvka over the closest vertex pairs between connected components (ties: smaller, then larger index);
    bridge weight WEIGHT_MIN * min(1, mean_edge_length^2 / d^2)."""
    n = len(ref)
    parent = list(range(n))

    def find(v):
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for i, j in edges:
        a, b = find(i), find(j)
        parent[max(a, b)] = min(a, b)
    mean_length = np.linalg.norm(ref[edges[:, 0]] - ref[edges[:, 1]], axis=1).mean() if len(edges) else 0.0
    new_edges, new_weights = [], []
    while True:
        roots = np.array([find(v) for v in range(n)])
        if (roots == roots[0]).all():
            break
        nearest, dist = np.zeros(n, dtype=np.int64), np.zeros(n)
        for start in range(0, n, 512):
            block = ref[start:start + 512]
            diff = block[:, None, :] - ref[None, :, :]
            d2 = diff[:, :, 0] ** 2 + diff[:, :, 1] ** 2 + diff[:, :, 2] ** 2
            d2[roots[start:start + 512, None] == roots[None, :]] = np.inf
            nearest[start:start + 512] = np.argmin(d2, axis=1)
            dist[start:start + 512] = d2[np.arange(len(block)), nearest[start:start + 512]]
        best = {}
        for i in range(n):
            key = (dist[i], min(i, nearest[i]), max(i, nearest[i]))
            if roots[i] not in best or key < best[roots[i]]:
                best[roots[i]] = key
        for d2, a, b in sorted(best.values()):
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
                new_edges.append((a, b))
                new_weights.append(WEIGHT_MIN * min(1.0, mean_length ** 2 / d2) if d2 > 0 else WEIGHT_MIN)
    if not new_edges:
        return edges, weights
    edges = np.concatenate([edges, np.array(new_edges, dtype=np.int64).reshape(-1, 2)])
    weights = np.concatenate([weights, np.array(new_weights)])
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    return edges[order], weights[order]


class Topology:
    def __init__(self, ref, faces):
        self.ref = np.asarray(ref, dtype=np.float64)
        self.n = n = len(self.ref)
        self.edges, self.weights = add_bridges(self.ref, *edge_weights(self.ref, faces))
        i, j = self.edges[:, 0], self.edges[:, 1]
        # Directed edge arrays (both directions) for the per-vertex sums.
        self.src = np.concatenate([i, j])
        self.dst = np.concatenate([j, i])
        self.w = np.concatenate([self.weights, self.weights])
        self.degree = np.bincount(self.src, minlength=n)
        e = self.ref[self.src] - self.ref[self.dst]
        a = np.zeros((n, 3, 3))
        np.add.at(a, self.src, self.w[:, None, None] * e[:, :, None] * e[:, None, :])
        self.trace = np.trace(a, axis1=1, axis2=2)
        self.lam = TIKHONOV * self.trace / 3.0
        self.a_reg = a + self.lam[:, None, None] * np.eye(3)
        # Sorted adjacency lists and components (seed = smallest index, BFS in ascending neighbour order).
        order = np.lexsort((self.dst, self.src))
        self.nbr_ptr = np.concatenate([[0], np.cumsum(self.degree)])
        self.nbr = self.dst[order]
        self.component = -np.ones(n, dtype=np.int64)
        self.seeds = []
        for s in range(n):
            if self.component[s] >= 0:
                continue
            cid = len(self.seeds)
            self.seeds.append(s)
            self.component[s] = cid
            queue = deque([s])
            while queue:
                v = queue.popleft()
                for u in self.nbr[self.nbr_ptr[v]:self.nbr_ptr[v + 1]]:
                    if self.component[u] < 0:
                        self.component[u] = cid
                        queue.append(u)
        # Laplacian with the seed of every component pinned, factorised once.
        lap = scipy.sparse.coo_matrix(
            (np.concatenate([-self.w, self.w]), (np.concatenate([self.src, self.src]),
                                                  np.concatenate([self.dst, self.src]))), shape=(n, n)).tocsc()
        self.free = np.setdiff1d(np.arange(n), np.array(self.seeds, dtype=np.int64))
        # Ring-moment operator: (M x)_i = sum_j c_ij (x_i - x_j) e_ij / sqrt(tr A_i), three rows per vertex.
        self.row_scale = np.where(self.trace > 0, 1.0 / np.sqrt(np.where(self.trace > 0, self.trace, 1.0)), 0.0)
        ws = self.w * self.row_scale[self.src]
        rows = np.concatenate([3 * self.src + k for k in range(3)] * 2)
        cols = np.concatenate([self.src] * 3 + [self.dst] * 3)
        vals = np.concatenate([ws * e[:, k] for k in range(3)] + [-ws * e[:, k] for k in range(3)])
        self.moment = scipy.sparse.coo_matrix((vals, (rows, cols)), shape=(3 * n, n)).tocsr()
        normal = (self.moment.T @ self.moment).tocsc()
        self.poisson_solver = self.moment_solver = None
        if len(self.free):
            self.poisson_solver = scipy.sparse.linalg.splu(lap[self.free][:, self.free].tocsc())
            self.moment_solver = scipy.sparse.linalg.splu(normal[self.free][:, self.free].tocsc())
        counts = np.bincount(self.component)
        self.ref_centroid = np.stack([np.bincount(self.component, weights=self.ref[:, k]) for k in range(3)], 1)
        self.ref_centroid /= counts[:, None]
        self.counts = counts

    def gradients(self, x):
        """T_i = (B_i + lambda_i K_i)(A_i + lambda_i I)^-1 with K_i the rotation of polar(B_i); identity where
        trace(A_i) = 0."""
        n = self.n
        e0 = self.ref[self.src] - self.ref[self.dst]
        e1 = x[self.src] - x[self.dst]
        b = np.zeros((n, 3, 3))
        np.add.at(b, self.src, self.w[:, None, None] * e1[:, :, None] * e0[:, None, :])
        kabsch, _ = polar(b)
        b += self.lam[:, None, None] * kabsch
        live = self.trace > 0
        t = np.tile(np.eye(3), (n, 1, 1))
        # T A = B  <=>  A^T T^T = B^T (A symmetric)
        t[live] = np.transpose(np.linalg.solve(self.a_reg[live], np.transpose(b[live], (0, 2, 1))), (0, 2, 1))
        return t


def polar(t):
    """T = R S with R in SO(3) and S symmetric (the smallest singular value carries the sign of det T)."""
    u, s, vt = np.linalg.svd(t)
    flip_u = np.linalg.det(u) < 0
    u[flip_u, :, 2] *= -1
    s[flip_u, 2] *= -1
    flip_v = np.linalg.det(vt) < 0
    vt[flip_v, 2, :] *= -1
    s[flip_v, 2] *= -1
    r = u @ vt
    sym = np.transpose(vt, (0, 2, 1)) @ (s[:, :, None] * vt)
    return r, 0.5 * (sym + np.transpose(sym, (0, 2, 1)))


def log_map(r):
    """Unit axis and angle in [0, pi] of each rotation; the axis is zero where the angle is zero."""
    cos = (np.trace(r, axis1=1, axis2=2) - 1.0) / 2.0
    vee = 0.5 * np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], 1)
    vn = np.linalg.norm(vee, axis=1)
    theta = np.arctan2(vn, cos)
    axis = np.zeros_like(vee)
    small = cos >= 0
    ok = small & (vn > 0)
    axis[ok] = vee[ok] / vn[ok, None]
    big = ~small
    if big.any():
        sym = 0.5 * (r[big] + np.transpose(r[big], (0, 2, 1))) - cos[big, None, None] * np.eye(3)
        col = np.argmax(np.diagonal(sym, axis1=1, axis2=2), axis=1)
        w = sym[np.arange(len(col)), :, col]
        w /= np.linalg.norm(w, axis=1)[:, None]
        sign = np.where(np.sum(w * vee[big], axis=1) < 0, -1.0, 1.0)
        axis[big] = w * sign[:, None]
    theta = np.where(np.linalg.norm(axis, axis=1) > 0, theta, 0.0)
    return axis, theta


def choose(r0, axis, target):
    """The representative r0 + 2 pi k axis closest to target (a zero axis takes the target's direction)."""
    if not axis.any():
        tn = np.linalg.norm(target)
        if tn == 0:
            return r0
        axis = target / tn
    k = np.floor(np.dot(axis, target - r0) / (2 * np.pi) + 0.5)
    return r0 + 2 * np.pi * k * axis


def consistent_rotations(topo, axis, theta, previous_seeds):
    """As-consistent-as-possible rotation vectors: per component, the seed is chosen closest to its value in the
    previous frame (zero for the first), then BFS in ascending order; each newly reached vertex is chosen closest
    to the mean of its already assigned neighbours."""
    n = topo.n
    r0 = axis * theta[:, None]
    out = np.zeros((n, 3))
    done = np.zeros(n, dtype=bool)
    for cid, s in enumerate(topo.seeds):
        out[s] = choose(r0[s], axis[s], previous_seeds[cid])
        done[s] = True
        queue = deque([s])
        while queue:
            v = queue.popleft()
            for u in topo.nbr[topo.nbr_ptr[v]:topo.nbr_ptr[v + 1]]:
                if done[u]:
                    continue
                nb = topo.nbr[topo.nbr_ptr[u]:topo.nbr_ptr[u + 1]]
                nb = nb[done[nb]]
                out[u] = choose(r0[u], axis[u], out[nb].mean(axis=0))
                done[u] = True
                queue.append(u)
    return out


def features(topo, frames):
    """[T, N, 9] features: rotation vector (3) then S00, S01, S02, S11, S12, S22."""
    previous = np.zeros((len(topo.seeds), 3))
    out = []
    for x in frames:
        rot, sym = polar(topo.gradients(np.asarray(x, dtype=np.float64)))
        axis, theta = log_map(rot)
        rv = consistent_rotations(topo, axis, theta, previous)
        previous = rv[topo.seeds]
        s6 = sym[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
        out.append(np.concatenate([rv, s6], axis=1))
    return np.stack(out)


def exp_map(rv):
    theta = np.linalg.norm(rv, axis=1)
    axis = np.where(theta[:, None] > 0, rv / np.where(theta > 0, theta, 1.0)[:, None], 0.0)
    kx = np.zeros((len(rv), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    kx = kx - np.transpose(kx, (0, 2, 1))
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * kx + (1 - c) * (kx @ kx)


def gradients_from_features(feats):
    rv, s6 = feats[:, :3], feats[:, 3:]
    sym = np.stack([s6[:, [0, 1, 2]], s6[:, [1, 3, 4]], s6[:, [2, 4, 5]]], axis=1)
    return exp_map(rv) @ sym


def place(topo, p):
    """Moves each component so that its centroid equals its reference centroid."""
    centroid = np.stack([np.bincount(topo.component, weights=p[:, k]) for k in range(3)], 1) / topo.counts[:, None]
    return p + (topo.ref_centroid - centroid)[topo.component]


def reconstruct_edge_poisson(topo, feats):
    """Gao et al.: L p = b with b_i = sum_j c_ij (T_i + T_j)/2 (q_i - q_j); each component's seed pinned."""
    t = gradients_from_features(feats)
    e0 = topo.ref[topo.src] - topo.ref[topo.dst]
    rhs_e = 0.5 * np.einsum("eab,eb->ea", t[topo.src] + t[topo.dst], e0) * topo.w[:, None]
    b = np.zeros((topo.n, 3))
    np.add.at(b, topo.src, rhs_e)
    p = np.zeros((topo.n, 3))
    if topo.poisson_solver is not None:
        p[topo.free] = topo.poisson_solver.solve(b[topo.free])
    return place(topo, p)


def reconstruct_ring_moments(topo, feats):
    """min sum_i |B_i(p) - G_i|^2 / tr A_i with G_i = T_i (A_i + lam I) - lam rot(T_i (A_i + lam I))."""
    ta = gradients_from_features(feats) @ topo.a_reg
    rot, _ = polar(ta)
    g = (ta - topo.lam[:, None, None] * rot) * topo.row_scale[:, None, None]
    # Row 3i + k of the target, column r (coordinate): G_i[r, k].
    target = np.transpose(g, (0, 2, 1)).reshape(3 * topo.n, 3)
    p = np.zeros((topo.n, 3))
    if topo.moment_solver is not None:
        p[topo.free] = topo.moment_solver.solve((topo.moment.T @ target)[topo.free])
    return place(topo, p)


METHODS = {"ring_moments": reconstruct_ring_moments, "edge_poisson": reconstruct_edge_poisson}


def load(path):
    with open(path) as f:
        data = json.load(f)
    return np.asarray(data["frames"], dtype=np.float64), data["faces"]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--features", nargs=2, metavar=("IN", "OUT"))
    parser.add_argument("--bench", metavar="IN")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--method", choices=sorted(METHODS), default="ring_moments")
    args = parser.parse_args()
    if args.features:
        frames, faces = load(args.features[0])
        topo = Topology(frames[0], faces)
        feats = features(topo, frames)
        out = {"features": feats.tolist()}
        for name, method in METHODS.items():
            out[name] = np.stack([method(topo, f) for f in feats]).tolist()
        with open(args.features[1], "w") as f:
            json.dump(out, f)
    elif args.bench:
        frames, faces = load(args.bench)
        best = None
        for _ in range(max(args.repeat, 1)):
            t0 = time.perf_counter()
            topo = Topology(frames[0], faces)
            feats = features(topo, frames)
            t1 = time.perf_counter()
            for f in feats:
                METHODS[args.method](topo, f)
            t2 = time.perf_counter()
            run = (t1 - t0, t2 - t1)
            best = run if best is None or sum(run) < sum(best) else best
        print(json.dumps({"vertices": int(frames.shape[1]), "frames": int(frames.shape[0]), "method": args.method,
                          "features_s": best[0], "reconstruction_s": best[1], "total_s": sum(best)}))
    else:
        parser.print_help()
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
