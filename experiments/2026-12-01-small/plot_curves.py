#!/usr/bin/env python3
"""Learning curves of the small runs: validation metrics against optimiser steps and against wall time.

Usage: python3 plot_curves.py RUNS_DIR OUT_DIR
RUNS_DIR holds the run folders `vae`, `rf`, `baseline-rf` (each with metrics.csv and valid.csv; the RF runs also
samples.csv). Wall time is the cumulative sum of 1 / steps_per_s over the training steps in metrics.csv (pauses
for validation and checkpoints are not counted). Writes curves.csv and curves_*.png into OUT_DIR.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def wall_clock(metrics):
    """step -> cumulative training seconds."""
    out, t = {}, 0.0
    for row in metrics:
        sps = float(row["steps_per_s"])
        if sps > 0:
            t += 1.0 / sps
        out[int(row["step"])] = t
    return out


def main(runs, out):
    os.makedirs(out, exist_ok=True)
    rows = []
    panels = [
        ("vae", "valid.csv", "rec", "VAE validation reconstruction (mean per-vertex distance)"),
        ("rf", "valid.csv", "rf", "RF validation loss (ours)"),
        ("baseline-rf", "valid.csv", "rf", "RF validation loss (Baseline)"),
        ("rf", "samples.csv", "rmse", "RF validation samples RMSE (ours, 8 clips, 16-point grid)"),
        ("baseline-rf", "samples.csv", "rmse", "RF validation samples RMSE (Baseline, 8 clips, 16-point grid)"),
    ]
    fig, axes = plt.subplots(len(panels), 2, figsize=(10, 3 * len(panels)))
    for i, (run, file, key, title) in enumerate(panels):
        path = os.path.join(runs, run, file)
        if not os.path.exists(path):
            for ax in axes[i]:
                ax.set_title(f"{title}: no {run}/{file}", fontsize=8)
            continue
        clock = wall_clock(read(os.path.join(runs, run, "metrics.csv")))
        data = [(int(r["step"]), float(r[key])) for r in read(path)]
        steps = [s for s, _ in data]
        values = [v for _, v in data]
        minutes = [clock.get(s, float("nan")) / 60 for s in steps]
        for s, m, v in zip(steps, minutes, values):
            rows.append({"run": run, "metric": f"{file[:-4]}.{key}", "step": s, "train_minutes": f"{m:.2f}", "value": v})
        axes[i][0].plot(steps, values, "o-")
        axes[i][0].set_xlabel("step")
        axes[i][1].plot(minutes, values, "o-")
        axes[i][1].set_xlabel("training minutes (2-core CPU, shared)")
        for ax in axes[i]:
            ax.set_title(title, fontsize=8)
            ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "curves.png"), dpi=90)
    with open(os.path.join(out, "curves.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["run", "metric", "step", "train_minutes", "value"])
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
