#!/usr/bin/env python3
"""numpy reference for the scene features (S1)–(S2) of data/src/scene/features.rs (docs/method.md §4.11), written
independently of it: the nearest point of a triangle as the nearer of the foot of the perpendicular on its plane
(when it falls inside, by barycentric coordinates) and the nearest points of its three edge segments; inside from the
solid-angle winding number of Van Oosterom and Strackee.

  python3 scripts/scene_features_reference.py INPUT.json
  python3 scripts/scene_features_reference.py --bench CLIPS.json --repeat R    # `any4d bench scene`

INPUT holds {"vertices": [[x, y, z], …], "faces": [[i, j, k], …], "cells": [gx, gy, gz], "cell": h,
"center": [x, y, z], "points": [[x, y, z], …]}; prints {"grid": [0/1 per cell, (i·gy + j)·gz + k], "offsets": [[dx,
dy, dz] per point]}. With --bench, CLIPS holds {"clips": [INPUT, …]} and one line {"clips": n,
"seconds_per_clip": s} is printed: the fastest of R passes over all clips, per clip.
"""

import json
import sys

import numpy as np


def segment_nearest(p, a, b):
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return a + t[:, None] * ab


def nearest_point(p, tri):
    """The point of the triangles tri (M, 3, 3) nearest to p (3,), and its distance."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    pp = np.broadcast_to(p, a.shape)
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 1e-300
    t = np.where(ok, np.einsum("ij,ij->i", pp - a, n) / np.where(ok, nn, 1.0), 0.0)
    foot = pp - t[:, None] * n
    inside = ok.copy()
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, foot - u), n) >= 0.0
    candidates = [np.where(inside[:, None], foot, np.inf)]
    candidates += [segment_nearest(pp, u, v) for u, v in ((a, b), (b, c), (c, a))]
    pts = np.stack(candidates, axis=1).reshape(-1, 3)
    d = np.linalg.norm(pts - p, axis=1)
    d[~np.isfinite(d)] = np.inf
    i = int(np.argmin(d))
    return pts[i], d[i]


def winding(p, tri):
    a, b, c = tri[:, 0] - p, tri[:, 1] - p, tri[:, 2] - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    den = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la
    return float(np.sum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi))


def features(inp):
    v = np.asarray(inp["vertices"], dtype=np.float64)
    tri = v[np.asarray(inp["faces"], dtype=np.int64)]
    gx, gy, gz = inp["cells"]
    h = float(np.float32(inp["cell"]))
    center = np.asarray(inp["center"], dtype=np.float32).astype(np.float64)
    reach = h * np.sqrt(3.0) / 2.0
    grid = []
    for i in range(gx):
        for j in range(gy):
            for k in range(gz):
                q = center + h * (np.array([i, j, k], dtype=np.float64) - (np.array([gx, gy, gz]) - 1.0) / 2.0)
                _, d = nearest_point(q, tri)
                signed = -d if winding(q, tri) > 0.5 else d
                grid.append(1.0 if signed <= reach else 0.0)
    offsets = []
    for p in np.asarray(inp["points"], dtype=np.float32).astype(np.float64):
        q, _ = nearest_point(p, tri)
        offsets.append((q - p).tolist())
    return grid, offsets


def main():
    if sys.argv[1] == "--bench":
        import time

        clips = json.load(open(sys.argv[2]))["clips"]
        repeat = int(sys.argv[4]) if len(sys.argv) > 4 and sys.argv[3] == "--repeat" else 3
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            for c in clips:
                features(c)
            best = min(best, time.perf_counter() - t0)
        print(json.dumps({"clips": len(clips), "seconds_per_clip": best / len(clips)}))
        return
    grid, offsets = features(json.load(open(sys.argv[1])))
    print(json.dumps({"grid": grid, "offsets": offsets}))


if __name__ == "__main__":
    main()
