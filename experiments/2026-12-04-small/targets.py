#!/usr/bin/env python3
"""The small family's targets (the table of README.md § 10) across every recipe measured so far, from committed
result files only.

Writes targets.csv (one row per recipe and K_x) and targets.png (three panels: ours / lerp, ours / the Baseline,
ours' pooled jerk / the ground truth's, each with its target line). The recipes, in the order they were run:

  b32x1500, b32x3000: ours at batch 32 on the 1,500-step VAE (../2026-12-04-rf-scale, 16-point grid, 3 seeds;
                      steps.csv);
  b32x4500:           the same at 4,500 steps, 64-point grid, 3 seeds (g64-vs-lerp.csv, baseline4500-3seeds.csv);
  b16x9000:           batch 16 x 9,000 steps on the 1,500-step VAE (../2026-12-05-rf-batch16/g64-targets.csv);
  b16x9000-v2000:     the same recipe on the 2,000-step VAE, the shipped family
                      (../2026-12-05-vae2000-family/g64-targets.csv).

The VAE's floor (vae_oracle: every ground-truth frame through the VAE, keyframes replaced) is drawn for both VAEs,
and the mean of eight samples of the shipped RF (../2026-12-05-tau-finetune/mean8-vs-one-s42.csv, seed 42 only) as
a marker: it is not the paper's method, it shows how much of the jerk is sample-to-sample variance.
"""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
exp = os.path.dirname(here)


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def by_row(path):
    """{(k, row name): csv row} of a compare.py table."""
    return {(int(r["k_extra"]), r["row"]): r for r in rows(path)}


def oracle(path):
    return {int(r["k_extra"]): float(r["jerk_pooled_mean"]) for r in rows(path) if r["method"] == "vae_oracle"}


KS = [0, 1, 2, 3]
steps = {(int(r["k_extra"]), int(r["rf_steps"])): r for r in rows(f"{here}/steps.csv")}
g4500 = by_row(f"{here}/baseline4500-3seeds.csv")
b16 = by_row(f"{exp}/2026-12-05-rf-batch16/g64-targets.csv")
v2000 = by_row(f"{exp}/2026-12-05-vae2000-family/g64-targets.csv")
mean8 = by_row(f"{exp}/2026-12-05-tau-finetune/mean8-vs-one-s42.csv")
floor1500 = oracle(f"{here}/table1-vae-oracle/summary.csv")
floor2000 = oracle(f"{exp}/2026-12-05-vae2000-family/table1-vae-oracle/summary.csv")

LERP = {k: float(g4500[(k, "lerp")]["rmse_x100"]) for k in KS}

recipes = []  # (name, {k: dict of figures})
for s in (1500, 3000):
    recipes.append((f"b32x{s}", {k: {
        "rmse_x100": float(steps[(k, s)]["rmse_x100"]),
        "over_lerp": float(steps[(k, s)]["rmse_over_lerp"]),
        "over_baseline1500": float("nan"),
        "over_baseline4500": float("nan"),
        "jerk": float(steps[(k, s)]["pooled_jerk_over_gt"]),
        "vae_floor_jerk": floor1500[k],
        "grid": 16, "seeds": "42-44",
    } for k in KS}))


def g64(name, table, b1500, b4500, floor):
    figs = {}
    for k in KS:
        ours = float(table[(k, "ours")]["rmse_x100"])
        figs[k] = {
            "rmse_x100": ours,
            "over_lerp": ours / float(table[(k, "lerp")]["rmse_x100"]),
            "over_baseline1500": ours / float(table[(k, b1500)]["rmse_x100"]),
            "over_baseline4500": ours / float(table[(k, b4500)]["rmse_x100"]) if b4500 else float("nan"),
            "jerk": float(table[(k, "ours")]["pooled_jerk_over_gt"]),
            "vae_floor_jerk": floor[k],
            "grid": 64, "seeds": "42-44",
        }
    recipes.append((name, figs))


g64("b32x4500", g4500, "b1500", "b4500", floor1500)
g64("b16x9000", b16, "baseline", "baseline4500", floor1500)
g64("b16x9000-v2000", v2000, "baseline", None, floor2000)

with open(f"{here}/targets.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["recipe", "k_extra", "grid", "seeds", "ours_rmse_x100", "ours_over_lerp", "ours_over_baseline1500",
                "ours_over_baseline4500", "ours_pooled_jerk_over_gt", "vae_floor_pooled_jerk_over_gt",
                "mean8_pooled_jerk_over_gt"])
    for name, figs in recipes:
        for k in KS:
            r = figs[k]
            m8 = float(mean8[(k, "mean8")]["pooled_jerk_over_gt"]) if name == "b16x9000-v2000" else float("nan")
            w.writerow([name, k, r["grid"], r["seeds"], f"{r['rmse_x100']:.3f}", f"{r['over_lerp']:.3f}",
                        f"{r['over_baseline1500']:.3f}", f"{r['over_baseline4500']:.3f}", f"{r['jerk']:.3f}",
                        f"{r['vae_floor_jerk']:.3f}", f"{m8:.3f}"])

names = [n for n, _ in recipes]
xs = list(range(len(names)))
colours = {k: f"C{k}" for k in KS}
fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
for k in KS:
    c = colours[k]
    axes[0].plot(xs, [f[k]["over_lerp"] for _, f in recipes], "o-", color=c, label=f"K_x {k}")
    axes[1].plot(xs, [f[k]["over_baseline1500"] for _, f in recipes], "o-", color=c, label=f"K_x {k}")
    axes[1].plot(xs, [f[k]["over_baseline4500"] for _, f in recipes], "s", color=c, mfc="none")
    axes[2].plot(xs, [f[k]["jerk"] for _, f in recipes], "o-", color=c, label=f"K_x {k}")
    axes[2].plot(xs, [f[k]["vae_floor_jerk"] for _, f in recipes], ":", color=c, lw=1)
    axes[2].plot([xs[-1]], [float(mean8[(k, "mean8")]["pooled_jerk_over_gt"])], "*", color=c, ms=10)
axes[0].axhline(0.7, color="k", ls="--", lw=1, label="target at K_x 0")
axes[0].axhline(1.0, color="grey", ls=":", lw=1, label="lerp")
axes[0].set_ylabel("ours' RMSE / lerp's")
axes[1].axhline(0.5, color="k", ls="--", lw=1, label="target 0.5")
axes[1].set_ylabel("ours' RMSE / the Baseline's\n(dots: 1,500-step Baseline; squares: 4,500-step)")
axes[2].axhline(1.5, color="k", ls="--", lw=1, label="target 1.5")
axes[2].set_ylabel("pooled jerk / ground truth's\n(dotted: VAE floor; stars: mean of 8 samples)")
for ax in axes:
    ax.set_xticks(xs)
    ax.set_xticklabels(names, rotation=20, fontsize=8)
    ax.set_xlabel("RF recipe (batch x steps; -v2000: the 2,000-step VAE)")
    ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{here}/targets.png", dpi=110)
print("wrote targets.csv, targets.png")
