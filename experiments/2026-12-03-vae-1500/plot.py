#!/usr/bin/env python3
"""Writes curves.csv (VAE validation reconstruction against steps: the shipped 750-step run and this 1,500-step one),
summary.csv (table 5 and latent lerp ÷ lerp per VAE) and curves.png, from the committed result folders."""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
# The shipped VAE's validation curve, as committed by experiments/2026-12-02-small-w256.
shipped = [(int(r["step"]), float(r["value"])) for r in csv.DictReader(open(f"{here}/../2026-12-02-small-w256/curves.csv"))
           if r["run"] == "vae" and r["metric"] == "valid.rec"]
new = [(int(r["step"]), float(r["rec"])) for r in csv.DictReader(open(f"{here}/vae-run/valid.csv"))]
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["vae", "step", "valid_rec"])
    w.writerows([("shipped-750", s, v) for s, v in shipped] + [("1500", s, v) for s, v in new])


def table5(folder):
    r = next(csv.DictReader(open(f"{here}/{folder}/summary.csv")))
    return float(r["rmse_mean"]) * 100, float(r["chamfer_mean"]) * 100


def ratios(folder):
    rows = {(r["method"], r["k_extra"]): float(r["rmse_mean"]) for r in csv.DictReader(open(f"{here}/{folder}/summary.csv"))}
    return [rows[("lerp_latent", str(k))] / rows[("lerp", str(k))] for k in range(4)]


with open(f"{here}/summary.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["vae", "steps", "table5_rmse_x100_mean", "table5_chamfer_x100_mean", "table5_rmse_x100_sample",
                "latent_lerp_over_lerp_k0", "k1", "k2", "k3"])
    for name, steps, t5, t5s, ll in [("weights/small/vae", 750, "table5-shipped", None, "latent-lerp-shipped"),
                                     ("runs/vae-1500-1", 1500, "table5", "table5-sample", "latent-lerp-v1500")]:
        rm, ch = table5(t5)
        rs = f"{table5(t5s)[0]:.2f}" if t5s else ""
        w.writerow([name, steps, f"{rm:.2f}", f"{ch:.2f}", rs] + [f"{x:.3f}" for x in ratios(ll)])

fig, ax = plt.subplots(figsize=(5.5, 3.5))
ax.plot(*zip(*shipped), "o-", label="shipped (750 steps, one device)")
ax.plot(*zip(*new), "o-", label="1,500 steps, two CPU workers")
ax.set_xlabel("step")
ax.set_ylabel("validation reconstruction (mean per-vertex distance)")
ax.set_yscale("log")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=120)
