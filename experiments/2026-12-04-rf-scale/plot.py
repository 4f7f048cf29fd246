#!/usr/bin/env python3
"""Writes curves.csv and curves.png: validation RF loss and validation samples (8 clips, 16-point grid) against
steps for the small RF preset at 1,500 steps (experiments/2026-12-03-vae-1500/rf-run) and at 3,000 (rf-run/), both
on the same 1,500-step VAE; and summary.csv, the table-1 RMSE of ours against lerp (and the Baseline, where its
folder exists) over the three sampler seeds, from the committed clips.parquet files."""
import csv
import os

import matplotlib
import pyarrow.parquet as pq

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
runs = {"1500 steps": f"{here}/../2026-12-03-vae-1500/rf-run", "3000 steps": f"{here}/rf-run"}


def rows(path):
    return list(csv.DictReader(open(path)))


curves = []
for name, folder in runs.items():
    for r in rows(f"{folder}/valid.csv"):
        curves.append((name, int(r["step"]), "valid_loss", float(r["rf"])))
    for r in rows(f"{folder}/samples.csv"):
        curves.append((name, int(r["step"]), "valid_sample_rmse", float(r["rmse"])))
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["run", "step", "metric", "value"])
    w.writerows(curves)

fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
for ax, metric, label in [(axes[0], "valid_loss", "validation RF loss"),
                          (axes[1], "valid_sample_rmse", "validation samples RMSE (8 clips)")]:
    for name in runs:
        pts = sorted((s, v) for n, s, m, v in curves if n == name and m == metric)
        ax.plot(*zip(*pts), "o-", label=name)
    ax.set_xlabel("step")
    ax.set_ylabel(label)
    ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=120)


def table(files, method):
    """Mean RMSE ×100 per K_x over every (clip, seed) row of `method` in the listed parquet files."""
    acc = {}
    for path in files:
        t = pq.read_table(f"{here}/{path}").to_pydict()
        for m, k, rmse in zip(t["method"], t["k_extra"], t["rmse"]):
            if m == method:
                acc.setdefault(int(k), []).append(rmse * 100)
    return {k: sum(v) / len(v) for k, v in sorted(acc.items())}


ours_files = ["table1-s42/clips.parquet", "table1-s43-44/clips.parquet"]
ours = table(ours_files, "keyframe_rf")
lerp = table(ours_files, "lerp")
before = table(["../2026-12-03-vae-1500/table1-rf-s42/clips.parquet",
                "../2026-12-03-vae-1500/table1-rf-s43-44/clips.parquet"], "keyframe_rf")
base_files = ["table1-baseline/clips.parquet"]
baseline = table(base_files, "replacement_rf") if os.path.exists(f"{here}/{base_files[0]}") else {}
with open(f"{here}/summary.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["k_extra", "ours_3000_rmse_x100", "ours_1500_rmse_x100", "lerp_rmse_x100", "baseline_rmse_x100",
                "ours_3000_over_lerp", "ours_1500_over_lerp", "ours_3000_over_baseline"])
    for k in ours:
        b = baseline.get(k)
        w.writerow([k, f"{ours[k]:.3f}", f"{before[k]:.3f}", f"{lerp[k]:.3f}", f"{b:.3f}" if b else "",
                    f"{ours[k] / lerp[k]:.3f}", f"{before[k] / lerp[k]:.3f}", f"{ours[k] / b:.3f}" if b else ""])
