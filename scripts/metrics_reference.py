#!/usr/bin/env python3
"""Independent numpy + scipy reference for the evaluation metrics of docs/method.md §6.1-§6.2 ((E1)-(E3), (E5)-(E7)).

Written separately from eval/src/metrics.rs so the Rust test compares two implementations, not one.

Modes:
  --write-fixtures PATH   write eval/tests/fixtures/metrics_reference.json (inputs and expected values)
  --bench FILE --clips C --frames T --vertices N --keyframes 0,15 [--rate R] [--repeat K]
                          time the reference on clips stored by `any4d bench metrics` (little-endian f32,
                          per clip: prediction [T, N, 3] then ground truth [T, N, 3]); prints one JSON object.
                          Run with OMP_NUM_THREADS=1 for a one-core reference.
"""

import argparse
import json
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

FIXTURE_SEEDS = (11, 12, 13)


def normalise_by_gt(pred, gt):
    """(D1)-(D3) from ground-truth frame 0, in float32 like the Rust data crate; returns float32 copies."""
    f0 = gt[0].astype(np.float32)
    lo, hi = f0.min(axis=0), f0.max(axis=0)
    centre = (hi + lo) / np.float32(2.0)
    scale = np.abs(f0 - centre).max() + np.float32(1e-8)
    return (pred - centre) / scale, (gt - centre) / scale


def dtw_normalised(a, b):
    """Centroid DTW (E3): min summed cost over steps (1,0),(0,1),(1,1), divided by the length of the backtracked path
    (tie order: diagonal, then (i-1, j), then (i, j-1))."""
    n, m = len(a), len(b)
    cost = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2))
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            acc[i, j] = cost[i - 1, j - 1] + min(acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1])
    i, j, length = n, m, 1
    while (i, j) != (1, 1):
        options = [(acc[i - 1, j - 1], i - 1, j - 1), (acc[i - 1, j], i - 1, j), (acc[i, j - 1], i, j - 1)]
        best = options[0]
        for option in options[1:]:
            if option[0] < best[0]:
                best = option
        _, i, j = best
        length += 1
    return acc[n, m] / length


def chamfer_frames(p, g):
    """(E2): per frame, mean NN distance g->p plus p->g, averaged over frames (scipy cKDTree, exact)."""
    total = 0.0
    for pf, gf in zip(p, g):
        total += cKDTree(pf).query(gf)[0].mean() + cKDTree(gf).query(pf)[0].mean()
    return total / len(p)


def mean_diff_norm(x, order, scale):
    """Mean over frames and vertices of the norm of the order-th forward difference, times scale ((E5), (E6))."""
    return float(np.linalg.norm(np.diff(x, n=order, axis=0), axis=2).mean() * scale)


def evaluate(pred, gt, keyframes, rate=1.0):
    """All metrics of one clip by docs/method.md §6.1; pred, gt float32 [T, N, 3]."""
    pn, gn = normalise_by_gt(pred, gt)
    p, g = pn.astype(np.float64), gn.astype(np.float64)
    frames = g.shape[0]
    keys = sorted(set(keyframes))
    scored = [f for f in range(frames) if f not in set(keys)]
    keyframe_rmse = float(np.sqrt(((p[keys] - g[keys]) ** 2).mean()))  # (E7) before replacement
    p[keys] = g[keys]
    du = p[scored] - g[scored]
    out = {
        "rmse": float(np.sqrt((du ** 2).mean())),
        "mae_elem": float(np.abs(du).mean()),
        "chamfer": float(chamfer_frames(p[scored], g[scored])),
        "dtw": float(dtw_normalised(p[scored].mean(axis=1), g[scored].mean(axis=1))),
        "jerk": mean_diff_norm(p, 3, rate ** 3),
        "jerk_gt": mean_diff_norm(g, 3, rate ** 3),
        "accel": mean_diff_norm(p, 2, rate ** 2),
        "accel_gt": mean_diff_norm(g, 2, rate ** 2),
        "energy": mean_diff_norm(p, 1, 1.0),
        "energy_gt": mean_diff_norm(g, 1, 1.0),
        "keyframe_rmse": keyframe_rmse,
        "mean_vertex_error": float(np.linalg.norm(du, axis=2).mean()),
    }
    out["jerk_ratio"] = out["jerk"] / out["jerk_gt"]
    out["accel_ratio"] = out["accel"] / out["accel_gt"]
    out["energy_ratio"] = out["energy"] / out["energy_gt"]
    return out


def raw_metrics(pred, gt):
    """RMSE, Chamfer and DTW over all frames without normalisation (tests the bare metric functions)."""
    p, g = pred.astype(np.float64), gt.astype(np.float64)
    return {
        "rmse": float(np.sqrt(((p - g) ** 2).mean())),
        "chamfer": float(chamfer_frames(p, g)),
        "dtw": float(dtw_normalised(p.mean(axis=1), g.mean(axis=1))),
    }


def make_case(seed, frames, n_vertices, keyframes, rate):
    """A moving random point cloud (offset and scaled so normalisation matters) and a noisy, drifting prediction."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(-1.0, 1.0, size=(n_vertices, 3)) * np.array([2.0, 1.0, 0.5]) + np.array([3.0, -1.0, 0.5])
    t = np.arange(frames)[:, None] / (frames - 1)  # [T, 1]
    angle = 1.5 * t
    x, y, z = base[None, :, 0], base[None, :, 1], base[None, :, 2]  # [1, N]
    gt = np.stack([np.cos(angle) * x - np.sin(angle) * z,
                   y + 0.3 * np.sin(4 * t),
                   np.sin(angle) * x + np.cos(angle) * z], axis=2)  # [T, N, 3]
    gt = gt + 0.05 * rng.standard_normal(gt.shape)
    drift = 0.2 * np.sin(np.pi * t)[:, :, None] * rng.standard_normal((1, 1, 3))
    pred = gt + drift + 0.03 * rng.standard_normal(gt.shape)
    return pred.astype(np.float32), gt.astype(np.float32)


def short(x):
    """Shortest decimal that reads back as the same float32."""
    return float(np.format_float_positional(np.float32(x), unique=True, trim="-"))


def write_fixtures(path):
    specs = [  # (seed, frames, vertices, keyframes, rate)
        (FIXTURE_SEEDS[0], 16, 24, [0, 15], 1.0),
        (FIXTURE_SEEDS[1], 16, 24, [0, 4, 9, 15], 10.0),
        (FIXTURE_SEEDS[2], 31, 12, [0, 15, 30], 1.0),
    ]
    cases = []
    for seed, frames, n, keys, rate in specs:
        pred, gt = make_case(seed, frames, n, keys, rate)
        cases.append({
            "seed": seed,
            "frames": frames,
            "n_vertices": n,
            "keyframes": keys,
            "rate": rate,
            "pred": [[short(c) for c in v] for v in pred.reshape(-1, 3)],
            "gt": [[short(c) for c in v] for v in gt.reshape(-1, 3)],
            "expected": evaluate(pred, gt, keys, rate),
            "raw": raw_metrics(pred, gt),
        })
    doc = {"generator": "python3 scripts/metrics_reference.py --write-fixtures " + path,
           "numpy": np.__version__, "cases": cases}
    with open(path, "w") as f:
        json.dump(doc, f, separators=(",", ":"))
        f.write("\n")


def bench(args):
    shape = (args.clips, 2, args.frames, args.vertices, 3)
    data = np.fromfile(args.bench, dtype="<f4")
    if data.size != np.prod(shape):
        sys.exit(f"{args.bench}: holds {data.size} floats, expected clips × 2 × T × N × 3 = {np.prod(shape)}")
    data = data.reshape(shape)
    keys = [int(k) for k in args.keyframes.split(",")]
    times, metrics = [], None
    for _ in range(args.repeat):
        start = time.perf_counter()
        metrics = [evaluate(data[c, 0], data[c, 1], keys, args.rate) for c in range(args.clips)]
        times.append(time.perf_counter() - start)
    seconds = float(np.median(times))
    print(json.dumps({"seconds": seconds, "clips_per_s": args.clips / seconds, "repeat": args.repeat,
                      "metrics": metrics}))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write-fixtures", metavar="PATH")
    parser.add_argument("--bench", metavar="FILE")
    parser.add_argument("--clips", type=int, default=8)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--vertices", type=int, default=4096)
    parser.add_argument("--keyframes", default="0,15")
    parser.add_argument("--rate", type=float, default=1.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    if args.write_fixtures:
        write_fixtures(args.write_fixtures)
    elif args.bench:
        bench(args)
    else:
        parser.error("give --write-fixtures PATH or --bench FILE")


if __name__ == "__main__":
    main()
