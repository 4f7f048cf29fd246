"""Rows of several table-1 runs on the same manifest, restricted to the (K_x, seed, item) triples they all hold:
RMSE / Chamfer / DTW x100, RMSE relative to lerp, pooled jerk / GT (sum of jerk over sum of GT jerk), and each
row's paired RMSE difference from the reference row (the first) with a 95 % bootstrap interval over clips.

usage: compare.py OUT.csv LABEL=PARQUET[+PARQUET...]:METHOD [LABEL=...] [--seeds 42,43]
(several files joined by + are one row's rows, e.g. one file per seed). The first row is the reference of the paired differences; a row labelled `lerp` is the denominator of the ratios."""
import sys, numpy as np, pyarrow.parquet as pq

args = sys.argv[2:]
seeds = None
if "--seeds" in args:
    i = args.index("--seeds")
    seeds = {int(s) for s in args[i + 1].split(",")}
    args = args[:i] + args[i + 2:]
rows = {}
for spec in args:
    label, rest = spec.split("=", 1)
    path, method = rest.rsplit(":", 1)
    rows[label] = {}
    for part in path.split("+"):
        t = pq.read_table(part).to_pydict()
        rows[label].update({
            (t["k_extra"][i], t["seed"][i], t["item"][i]): {c: t[c][i] for c in ("rmse", "chamfer", "dtw", "jerk", "jerk_gt")}
            for i in range(len(t["method"]))
            if t["method"][i] == method and (seeds is None or t["seed"][i] in seeds)
        })
common = set.intersection(*(set(r) for r in rows.values()))
labels = list(rows)
ref = labels[0]
rng = np.random.default_rng(0)
out = ["k_extra,row,windows,rmse_x100,chamfer_x100,dtw_x100,rmse_over_lerp,pooled_jerk_over_gt,"
       "diff_vs_ref_x100,diff_ci_lo,diff_ci_hi,wins_vs_ref"]
for k in sorted({key[0] for key in common}):
    keys = sorted(key for key in common if key[0] == k)
    items = sorted({key[2] for key in keys})
    mean = {l: {c: np.mean([rows[l][x][c] for x in keys]) for c in ("rmse", "chamfer", "dtw")} for l in labels}
    for l in labels:
        jerk = sum(rows[l][x]["jerk"] for x in keys) / max(sum(rows[l][x]["jerk_gt"] for x in keys), 1e-30)
        ratio = mean[l]["rmse"] / mean["lerp"]["rmse"] if "lerp" in rows else float("nan")
        per_item = np.array([np.mean([rows[l][x]["rmse"] - rows[ref][x]["rmse"] for x in keys if x[2] == it])
                             for it in items])
        boots = [rng.choice(per_item, len(per_item)).mean() for _ in range(4000)]
        lo, hi = np.percentile(boots, [2.5, 97.5])
        wins = np.mean([rows[l][x]["rmse"] < rows[ref][x]["rmse"] for x in keys])
        out.append(f"{k},{l},{len(keys)},{100*mean[l]['rmse']:.3f},{100*mean[l]['chamfer']:.3f},"
                   f"{100*mean[l]['dtw']:.3f},{ratio:.3f},{jerk:.3f},{100*per_item.mean():.3f},{100*lo:.3f},"
                   f"{100*hi:.3f},{wins:.3f}")
open(sys.argv[1], "w").write("\n".join(out) + "\n")
print("\n".join(out))
