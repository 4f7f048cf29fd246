"""Scene-RF variants against the RF told nothing, paired window by window (docs/method.md §4.12).

    python compare.py OUT.csv ref=PARQUET:METHOD name=PARQUET:METHOD ...

Per K_x and row: the mean over windows (each clip's seeds averaged first) of RMSE ×100, Chamfer ×100, the share of
frames in collision (%), the share of vertices inside the scene (%), the deepest penetration ×100 and foot skating
(%), and the row minus the first row on RMSE and on collision frames with a 95 % interval from 10,000 bootstrap draws
of the clips (each clip is its own object here: a procedural store draws every clip afresh). Needs numpy, pyarrow.
"""
import csv
import sys

import numpy as np
import pyarrow.parquet as pq

METRICS = [
    ("rmse_x100", "rmse", 100.0),
    ("chamfer_x100", "chamfer", 100.0),
    ("collision_frames_pct", "collision_frames", 100.0),
    ("collision_vertices_pct", "collision_vertices", 100.0),
    ("max_penetration_x100", "max_penetration", 100.0),
    ("foot_skating_pct", "foot_skating", 100.0),
]


def load(spec):
    path, method = spec.rsplit(":", 1)
    t = pq.read_table(path).to_pydict()
    out = {}  # (k, clip) -> {metric: [values over seeds]}
    for i, m in enumerate(t["method"]):
        if m != method:
            continue
        cell = out.setdefault((t["k_extra"][i], t["clip_id"][i]), {})
        for _, col, _ in METRICS:
            cell.setdefault(col, []).append(t[col][i])
    if not out:
        sys.exit(f"{path}: no rows of method {method}")
    return {key: {c: float(np.mean(v)) for c, v in cell.items()} for key, cell in out.items()}


def main():
    out_path, *pairs = sys.argv[1:]
    rows = [(p.split("=", 1)[0], load(p.split("=", 1)[1])) for p in pairs]
    ref_name, ref = rows[0]
    rng = np.random.default_rng(0)
    ks = sorted({k for k, _ in ref})
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["k_extra", "row", "windows"] + [m for m, _, _ in METRICS]
                   + ["rmse_diff_x100", "rmse_lo", "rmse_hi", "collision_frames_diff_pct", "cf_lo", "cf_hi"])
        for k in ks:
            clips = sorted(c for kk, c in ref if kk == k)
            draws = rng.integers(0, len(clips), size=(10_000, len(clips)))
            for name, data in rows:
                missing = [c for c in clips if (k, c) not in data]
                if missing:
                    sys.exit(f"{name}: K_x {k} lacks {len(missing)} windows of {ref_name}")
                vals = {col: np.array([data[(k, c)][col] for c in clips]) for _, col, _ in METRICS}
                means = [f"{vals[col].mean() * s:.4f}" for _, col, s in METRICS]
                diffs = []
                for col in ("rmse", "collision_frames"):
                    d = (vals[col] - np.array([ref[(k, c)][col] for c in clips])) * 100.0
                    boot = d[draws].mean(axis=1)
                    diffs += [f"{d.mean():.4f}", f"{np.percentile(boot, 2.5):.4f}", f"{np.percentile(boot, 97.5):.4f}"]
                w.writerow([k, name, len(clips)] + means + diffs)


if __name__ == "__main__":
    main()
