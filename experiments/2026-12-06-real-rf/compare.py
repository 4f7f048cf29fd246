"""Rows of several table-1 runs on the same windows, paired by (K_x, seed, window), with 95 % intervals of each
row's RMSE difference from the first row resampled BY OBJECT (every window and seed of a drawn object goes
together; an object is a clip id up to `_offset`), and each row's RMSE over lerp's.

usage: compare.py OUT.csv LABEL=PARQUET[+PARQUET...]:METHOD [LABEL=...]
The first row is the reference of the differences; a row labelled `lerp` is the denominator of the ratios. Beside
OUT.csv, OUT-by-object.csv holds each row's mean RMSE x100 per object and K_x."""

import sys

import numpy as np
import pyarrow.parquet as pq

COLUMNS = ("rmse", "chamfer", "dtw", "jerk", "jerk_gt")


def object_uid(clip_id: str) -> str:
    return clip_id.split("_offset")[0]


def load(spec):
    label, rest = spec.split("=", 1)
    path, method = rest.rsplit(":", 1)
    rows = {}
    for part in path.split("+"):
        t = pq.read_table(part).to_pydict()
        for i, m in enumerate(t["method"]):
            if m == method:
                key = (t["k_extra"][i], t["seed"][i], t["item"][i], t["clip_id"][i])
                rows[key] = {c: t[c][i] for c in COLUMNS}
    if not rows:
        sys.exit(f"{spec}: no rows of method {method}")
    return label, rows


def by_object_interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    means = sums[draws].sum(axis=1) / counts[draws].sum(axis=1)
    return np.percentile(means, [2.5, 97.5])


def main():
    rows = dict(load(spec) for spec in sys.argv[2:])
    labels = list(rows)
    common = set.intersection(*(set(r) for r in rows.values()))
    out = ["k_extra,row,window_seeds,objects,rmse_x100,chamfer_x100,dtw_x100,rmse_over_lerp,pooled_jerk_over_gt,"
           "diff_vs_ref_x100,diff_lo,diff_hi,wins_vs_ref"]
    for k in sorted({key[0] for key in common}):
        keys = sorted(key for key in common if key[0] == k)
        objects = np.array([object_uid(key[3]) for key in keys])
        value = {l: {c: np.array([rows[l][x][c] for x in keys]) for c in COLUMNS} for l in labels}
        for l in labels:
            v = value[l]
            jerk = v["jerk"].sum() / max(v["jerk_gt"].sum(), 1e-30)
            ratio = v["rmse"].mean() / value["lerp"]["rmse"].mean() if "lerp" in value else float("nan")
            diff = 100 * (v["rmse"] - value[labels[0]]["rmse"])
            lo, hi = by_object_interval(diff, objects)
            wins = np.mean(v["rmse"] < value[labels[0]]["rmse"])
            out.append(
                f"{k},{l},{len(keys)},{len(np.unique(objects))},{100 * v['rmse'].mean():.3f},"
                f"{100 * v['chamfer'].mean():.3f},{100 * v['dtw'].mean():.3f},{ratio:.3f},{jerk:.3f},"
                f"{diff.mean():.3f},{lo:.3f},{hi:.3f},{wins:.3f}"
            )
    open(sys.argv[1], "w").write("\n".join(out) + "\n")
    per = ["k_extra,object,window_seeds," + ",".join(labels)]
    for k in sorted({key[0] for key in common}):
        keys = sorted(key for key in common if key[0] == k)
        for obj in sorted({object_uid(key[3]) for key in keys}):
            mine = [x for x in keys if object_uid(x[3]) == obj]
            means = [100 * np.mean([rows[l][x]["rmse"] for x in mine]) for l in labels]
            per.append(f"{k},{obj},{len(mine)}," + ",".join(f"{m:.3f}" for m in means))
    open(sys.argv[1].removesuffix(".csv") + "-by-object.csv", "w").write("\n".join(per) + "\n")
    print("\n".join(out))


if __name__ == "__main__":
    main()
