#!/usr/bin/env python3
"""Writes curves.csv and curves.png (validation RF loss and the 8 validation samples' RMSE against training samples
seen, for the reference run and the two probes) from the committed run folders."""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
# (label, run folder, batch size)
runs = [("batch 32, 1,500 steps (reference)", f"{here}/../2026-12-03-vae-1500/rf-run", 32),
        ("batch 32, 3,000 steps", f"{here}/../2026-12-04-rf-scale/rf-run", 32),
        ("batch 32, 4,500 steps (shipped)", f"{here}/../2026-12-04-rf-scale/rf4500-run", 32),
        ("batch 32, 1,500 steps, lr 1e-3", f"{here}/lr1e3-run", 32),
        ("batch 16, 3,000 steps", f"{here}/b16-run", 16),
        ("batch 16, 4,500 steps", f"{here}/b16-4500-run", 16)]


def read(path, col):
    return [(int(r["step"]), float(r[col])) for r in csv.DictReader(open(path))]


rows = []
runs = [r for r in runs if os.path.exists(f"{r[1]}/valid.csv")]
for label, folder, batch in runs:
    loss = dict(read(f"{folder}/valid.csv", "loss"))
    rmse = dict(read(f"{folder}/samples.csv", "rmse"))
    for step in sorted(set(loss) | set(rmse)):
        rows.append((label, step, step * batch, loss.get(step, ""), rmse.get(step, "")))
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["run", "step", "samples_seen", "valid_rf_loss", "valid_samples_rmse"])
    w.writerows(rows)

fig, axes = plt.subplots(1, 2, figsize=(10, 4))
for label, folder, _ in runs:
    pts = [r for r in rows if r[0] == label]
    for ax, col in zip(axes, (3, 4)):
        xy = [(r[2], r[col]) for r in pts if r[col] != ""]
        ax.plot([x for x, _ in xy], [y for _, y in xy], marker="o", label=label)
axes[0].set_title("validation RF loss")
axes[1].set_title("RMSE of 8 validation samples (16-point grid)")
for ax in axes:
    ax.set_xlabel("training samples seen")
    ax.grid(alpha=0.3)
axes[0].legend(fontsize=8)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=110)
