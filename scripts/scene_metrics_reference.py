#!/usr/bin/env python3
"""numpy reference for the scene metrics (E8)–(E10) of eval/src/scene_metrics.rs (docs/method.md §6.5), written
independently of it: the distance to a triangle as the nearer of its plane (when the foot of the perpendicular falls
inside, by barycentric coordinates) and its three edge segments; the winding number from the solid angles of
Van Oosterom and Strackee.

  python3 scripts/scene_metrics_reference.py INPUT.json

INPUT holds {"vertices": [[x, y, z], …], "faces": [[i, j, k], …], "motion": [[[x, y, z], …] per frame],
"contact": c, "slide": s}; prints {"collision_frames", "collision_vertices", "max_penetration", "foot_skating"}.
"""

import json
import sys

import numpy as np


def segment_distance(p, a, b):
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def triangle_distances(p, tri):
    """Distances from point p (3,) to every triangle of tri (M, 3, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    pp = np.broadcast_to(p, a.shape)
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 1e-300
    t = np.where(ok, np.einsum("ij,ij->i", pp - a, n) / np.where(ok, nn, 1.0), 0.0)
    foot = pp - t[:, None] * n
    # Barycentric coordinates of the foot: inside when all three sub-triangles wind like the triangle.
    inside = ok.copy()
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, foot - u), n) >= 0.0
    plane = np.where(inside, np.abs(t) * np.sqrt(nn), np.inf)
    edges = np.minimum(np.minimum(segment_distance(pp, a, b), segment_distance(pp, b, c)), segment_distance(pp, c, a))
    return np.minimum(plane, edges)


def winding(p, tri):
    a, b, c = tri[:, 0] - p, tri[:, 1] - p, tri[:, 2] - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    return np.sum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi)


def main(path):
    with open(path) as f:
        d = json.load(f)
    verts = np.asarray(d["vertices"], dtype=np.float32).astype(np.float64)
    tri = verts[np.asarray(d["faces"], dtype=np.int64)]
    motion = np.asarray(d["motion"], dtype=np.float32).astype(np.float64)
    t, n, _ = motion.shape
    sd = np.empty((t, n))
    for f in range(t):
        for v in range(n):
            dist = triangle_distances(motion[f, v], tri).min()
            sd[f, v] = -dist if winding(motion[f, v], tri) > 0.5 else dist
    inside = sd < 0.0
    touching = np.abs(sd) <= d["contact"]
    slide = np.hypot(motion[1:, :, 0] - motion[:-1, :, 0], motion[1:, :, 2] - motion[:-1, :, 2])
    skating = (touching[:-1] & touching[1:] & (slide > d["slide"])).any(axis=1)
    print(json.dumps({
        "collision_frames": float(inside.any(axis=1).mean()),
        "collision_vertices": float(inside.mean()),
        "max_penetration": float(max(0.0, (-sd).max())),
        "foot_skating": float(skating.mean()),
    }))


if __name__ == "__main__":
    main(sys.argv[1])
