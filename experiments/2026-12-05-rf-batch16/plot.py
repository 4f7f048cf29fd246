#!/usr/bin/env python3
"""Writes curves.csv and curves.png: validation RF loss and the 8 validation samples' RMSE of the batch-16 run at
9,000 steps against the shipped batch-32 run at 4,500 steps (and batch 16 at 4,500), against training samples seen
and against training wall time (the cumulative sum of 1 / steps_per_s in each run's metrics.csv)."""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
# (label, run folder, batch size)
runs = [("batch 32, 4,500 steps (shipped before)", f"{here}/../2026-12-04-rf-scale/rf4500-run", 32),
        ("batch 16, 4,500 steps", f"{here}/../2026-12-04-rf-optim/b16-4500-run", 16),
        ("batch 16, 9,000 steps", f"{here}/b16-9000-run", 16)]


def read(path, col):
    return [(int(r["step"]), float(r[col])) for r in csv.DictReader(open(path))]


def elapsed(folder):
    """step → seconds of training steps up to it (start-up excluded)."""
    out, t = {}, 0.0
    for step, rate in read(f"{folder}/metrics.csv", "steps_per_s"):
        t += 1.0 / rate
        out[step] = t
    return out


rows = []
for label, folder, batch in runs:
    loss = dict(read(f"{folder}/valid.csv", "loss"))
    rmse = dict(read(f"{folder}/samples.csv", "rmse"))
    secs = elapsed(folder)
    for step in sorted(set(loss) | set(rmse)):
        rows.append((label, step, step * batch, round(secs.get(step, float("nan"))), loss.get(step, ""),
                     rmse.get(step, "")))
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["run", "step", "samples_seen", "step_seconds", "valid_rf_loss", "valid_samples_rmse"])
    w.writerows(rows)

fig, axes = plt.subplots(2, 2, figsize=(10, 7))
for label, _, _ in runs:
    pts = [r for r in rows if r[0] == label]
    for i, (xcol, xname) in enumerate(((2, "training samples seen"), (3, "seconds of training steps"))):
        for j, (ycol, yname) in enumerate(((4, "validation RF loss"), (5, "RMSE of 8 validation samples (16 points)"))):
            ax = axes[j][i]
            xy = [(r[xcol], r[ycol]) for r in pts if r[ycol] != ""]
            ax.plot([x for x, _ in xy], [y for _, y in xy], marker="o", label=label)
            ax.set_xlabel(xname)
            ax.set_title(yname)
            ax.grid(alpha=0.3)
axes[0][0].legend(fontsize=8)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=110)
