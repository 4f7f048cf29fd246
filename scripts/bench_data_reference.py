#!/usr/bin/env python3
"""Reference for `any4d bench data`: read DyMesh .bin clips with pickle.load, normalise them by frame 0 (docs/method.md §2.3,
(D1)-(D3)) with numpy and run farthest point sampling on normalised frame 0 (docs/method.md §2.5) with a vectorised numpy loop,
on one core.

Usage: python3 scripts/bench_data_reference.py DIR [--p 512]

Prints one JSON line: {"clips": n, "seconds": s, "clips_per_s": r, "fps_checksum": c}, where the checksum is the sum
of all FPS indices (the Rust side computes the same sum, so the two implementations can be compared).
"""

import os

# One core for numpy's BLAS/OpenMP pools; must be set before numpy is imported.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def normalize(vertices):
    """(T, N, 3) absolute positions -> positions normalised by frame 0, centre c, scale s."""
    f0 = vertices[0]
    c = (f0.max(axis=0) + f0.min(axis=0)) / 2  # (D1)
    s = np.abs(f0 - c).max() + np.float32(1e-8)  # (D2)
    return (vertices - c) / s, c, s  # (D3)


def farthest_point_sampling(points, p):
    """Start at index 0, squared distances, ties to the lowest index; chosen points are never chosen again."""
    n = points.shape[0]
    dist = np.full(n, np.inf, dtype=np.float32)
    out = np.empty(p, dtype=np.int64)
    cur = 0
    for k in range(min(p, n)):
        out[k] = cur
        diff = points - points[cur]
        d = (diff * diff).sum(axis=1)
        np.minimum(dist, d, out=dist)
        dist[cur] = -1.0
        cur = int(np.argmax(dist))
    for k in range(n, p):
        out[k] = out[k % n]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir")
    ap.add_argument("--p", type=int, default=512)
    args = ap.parse_args()
    files = sorted(f for f in os.listdir(args.dir) if f.endswith(".bin"))
    if not files:
        sys.exit(f"{args.dir}: no .bin files")
    checksum = 0
    start = time.perf_counter()
    for name in files:
        with open(os.path.join(args.dir, name), "rb") as fh:
            clip = pickle.load(fh)
        vertices = np.asarray(clip["vertices"], dtype=np.float32)
        normalised, _c, _s = normalize(vertices)
        checksum += int(farthest_point_sampling(normalised[0], args.p).sum())
    seconds = time.perf_counter() - start
    print(json.dumps({"clips": len(files), "seconds": seconds, "clips_per_s": len(files) / seconds, "fps_checksum": checksum}))


if __name__ == "__main__":
    main()
