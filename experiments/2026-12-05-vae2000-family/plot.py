#!/usr/bin/env python3
"""Writes curves.csv and curves.png: the VAE's validation reconstruction loss at 1,500 and 2,000 steps, and the
keyframe RF's validation loss and 8 validation samples' RMSE on each VAE (the same RF recipe: batch 16 × 9,000
steps), against steps and against the seconds of training steps (the cumulative sum of 1 / steps_per_s in each
run's metrics.csv; start-up excluded)."""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
# (model, label, run folder, columns of valid.csv / samples.csv to plot)
runs = [("vae", "VAE, 1,500 steps (shipped before)", f"{here}/../2026-12-03-vae-1500/vae-run"),
        ("vae", "VAE, 2,000 steps", f"{here}/vae-run"),
        ("rf", "ours on the 1,500-step VAE (shipped before)", f"{here}/../2026-12-05-rf-batch16/b16-9000-run"),
        ("rf", "ours on the 2,000-step VAE", f"{here}/rf-run")]


def read(path, col):
    if not os.path.exists(path):
        return []
    return [(int(r["step"]), float(r[col])) for r in csv.DictReader(open(path))]


def elapsed(folder):
    """step → seconds of training steps up to it."""
    out, t = {}, 0.0
    for step, rate in read(f"{folder}/metrics.csv", "steps_per_s"):
        t += 1.0 / rate
        out[step] = t
    return out


rows = []
for model, label, folder in runs:
    loss = dict(read(f"{folder}/valid.csv", "rec" if model == "vae" else "loss"))
    rmse = dict(read(f"{folder}/samples.csv", "rmse"))
    secs = elapsed(folder)
    for step in sorted(set(loss) | set(rmse)):
        rows.append((model, label, step, round(secs.get(step, float("nan"))), loss.get(step, ""), rmse.get(step, "")))
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["model", "run", "step", "step_seconds", "valid_loss", "valid_samples_rmse"])
    w.writerows(rows)

panels = [("vae", 4, "VAE validation reconstruction loss"), ("rf", 4, "RF validation loss"),
          ("rf", 5, "RF: RMSE of 8 validation samples (16 points)")]
fig, axes = plt.subplots(2, 3, figsize=(14, 7))
for i, (xcol, xname) in enumerate(((2, "step"), (3, "seconds of training steps"))):
    for j, (model, ycol, title) in enumerate(panels):
        ax = axes[i][j]
        for m, label, _ in runs:
            if m != model:
                continue
            xy = [(r[xcol], r[ycol]) for r in rows if r[1] == label and r[ycol] != ""]
            ax.plot([x for x, _ in xy], [y for _, y in xy], marker="o", label=label)
        ax.set_xlabel(xname)
        ax.set_title(title)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=110)
