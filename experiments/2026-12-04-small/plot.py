#!/usr/bin/env python3
"""Writes this experiment's result files from the committed run files:

- times.csv: each model's wall time in the from-scratch family run (family/), less the seconds it was paused;
- curves.csv, curves.png: validation curves against wall time of the family run, and the step rate against the step
  for the family run (subnormal floats flushed) and the runs that made weights/small (not flushed);
- steps.csv, jerk.png: ours' RMSE over lerp's and pooled jerk over the ground truth's against RF training steps
  (1,500 / 3,000 / 4,500, ../2026-12-04-rf-scale), with the floor the VAE sets (vae_oracle rows);
- summary.csv: the shipped family against lerp, the Baseline and the VAE's floor per K_x (100 clips x 3 seeds).
"""
import csv
import datetime
import os
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = os.path.dirname(os.path.abspath(__file__))
fam = f"{here}/family"
scale = f"{here}/../2026-12-04-rf-scale"


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


# ---- wall time of the family run, pauses removed --------------------------------------------------------------
day = datetime.datetime(2026, 12, 4, tzinfo=datetime.timezone.utc)
starts = {}
for line in open(f"{fam}/family.log"):
    m = re.match(r"\[(\d\d):(\d\d):(\d\d)\] (\w+):", line)
    if m:
        h, mi, s, name = int(m[1]), int(m[2]), int(m[3]), m[4]
        starts[name] = (day + datetime.timedelta(hours=h, minutes=mi, seconds=s)).timestamp()
pauses = []
if os.path.exists(f"{fam}/pauses.csv"):
    for line in open(f"{fam}/pauses.csv"):
        a, b, *_ = line.split(",")
        pauses.append((float(a), float(b)))
times = []
for r in rows(f"{fam}/times.csv"):
    name, secs = r["step"], float(r["seconds"])
    t0 = starts[name]
    paused = sum(max(0.0, min(b, t0 + secs + 1) - max(a, t0 - 1)) for a, b in pauses)
    times.append((name, secs, paused, secs - paused))
with open(f"{here}/times.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["step", "wall_s", "paused_s", "net_s"])
    for name, secs, paused, net in times:
        w.writerow([name, f"{secs:.0f}", f"{paused:.0f}", f"{net:.0f}"])
    train = [t for t in times if t[0] != "data"]
    w.writerow(["training (vae + rf + baseline)", f"{sum(t[1] for t in train):.0f}", f"{sum(t[2] for t in train):.0f}",
                f"{sum(t[3] for t in train):.0f}"])


# ---- curves ------------------------------------------------------------------------------------------------------
def elapsed(metrics):
    """Cumulative seconds of the steps (1 / steps_per_s per step), by step. A step more than 5x the run's median step
    time waited out a pause (pauses.csv: the run was stopped with SIGSTOP while other work used the CPU) or a
    checkpoint; it counts at the median."""
    times = [1.0 / float(r["steps_per_s"]) for r in metrics]
    median = sorted(times)[len(times) // 2]
    acc, out = 0.0, {}
    for r, t in zip(metrics, times):
        acc += t if t <= 5 * median else median
        out[int(r["step"])] = acc
    return out


models = {
    "vae": (f"{fam}/vae-run", f"{here}/../2026-12-03-vae-1500/vae-run", [("valid_rec", "valid.csv", "rec")]),
    "rf": (f"{fam}/rf-run", f"{scale}/rf4500-run",
           [("valid_loss", "valid.csv", "rf"), ("valid_sample_rmse", "samples.csv", "rmse")]),
    "baseline": (f"{fam}/baseline-run", f"{scale}/baseline-run", [("valid_loss", "valid.csv", "rf")]),
}
curves = []
rate = {}
for model, (run, before, series) in models.items():
    for label, folder in [("flushed (family run)", run), ("not flushed (weights/small, as it ran)", before)]:
        if not os.path.exists(f"{folder}/metrics.csv"):
            continue
        metrics = rows(f"{folder}/metrics.csv")
        # a resumed run repeats steps; keep the last row of each step
        by_step = {int(r["step"]): r for r in metrics}
        metrics = [by_step[s] for s in sorted(by_step)]
        clock = elapsed(metrics)
        if label.startswith("flushed"):
            rate[(model, label)] = [(int(r["step"]), float(r["steps_per_s"])) for r in metrics]
        for name, file, column in series:
            if not os.path.exists(f"{folder}/{file}"):
                continue
            for r in rows(f"{folder}/{file}"):
                s = int(r["step"])
                curves.append((model, label, name, s, clock.get(s, float("nan")) / 60, float(r[column])))
# The clean "before" of the step rate: the aborted first try of the family run (binary without the flush, CPU idle).
aborted = rows(f"{here}/noflush-aborted/vae-metrics.csv")
rate[("vae", "not flushed (aborted try, idle)")] = [(int(r["step"]), float(r["steps_per_s"])) for r in aborted]
with open(f"{here}/curves.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["model", "run", "metric", "step", "step_minutes", "value"])
    w.writerows(curves)

fig, axes = plt.subplots(1, 4, figsize=(16, 3.6))
panels = [("vae", "valid_rec", "VAE validation reconstruction"), ("rf", "valid_loss", "RF validation loss"),
          ("rf", "valid_sample_rmse", "RF validation samples RMSE (8 clips)")]
for ax, (model, metric, title) in zip(axes, panels):
    for label in ["flushed (family run)", "not flushed (weights/small, as it ran)"]:
        pts = sorted((m, v) for mo, lab, me, s, m, v in curves if mo == model and lab == label and me == metric)
        if pts:
            ax.plot(*zip(*pts), "o-", ms=3, label=label)
    ax.set_xlabel("minutes of training steps")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
ax = axes[3]
for (model, label), pts in sorted(rate.items()):
    steps = [s for s, _ in pts]
    # a rolling median: a step that waited out a pause (SIGSTOP, pauses.csv) is one outlier, not a dip
    smooth = [sorted(v for _, v in pts[max(0, i - 25):i + 26])[len(pts[max(0, i - 25):i + 26]) // 2]
              for i in range(len(pts))]
    ax.plot(steps, smooth, "-" if label.startswith("flushed") else "--", label=f"{model}, {label}")
ax.set_ylim(bottom=0)
ax.set_xlabel("step")
ax.set_ylabel("steps/s (51-step rolling median)")
ax.set_title("step rate on two CPU workers", fontsize=9)
ax.legend(fontsize=6)
fig.tight_layout()
fig.savefig(f"{here}/curves.png", dpi=110)


# ---- RMSE and jerk against RF steps, with the VAE's floor ---------------------------------------------------------
def compare_rows(path, row):
    return {int(r["k_extra"]): r for r in rows(path) if r["row"] == row}


by_steps = {1500: compare_rows(f"{scale}/vs-1500.csv", "v1500"), 3000: compare_rows(f"{scale}/vs-1500.csv", "v3000"),
            4500: compare_rows(f"{scale}/vs-4500.csv", "v4500")}


def table_rows(path, method):
    return {int(r["k_extra"]): r for r in rows(path) if r["method"] == method}


oracle = table_rows(f"{here}/table1-vae-oracle/summary.csv", "vae_oracle")
oracle750 = table_rows(f"{here}/table1-vae-oracle-750/summary.csv", "vae_oracle")
lerp42 = table_rows(f"{here}/table1-vae-oracle/summary.csv", "lerp")
with open(f"{here}/steps.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["k_extra", "rf_steps", "rmse_x100", "rmse_over_lerp", "pooled_jerk_over_gt"])
    for k in range(4):
        for steps, table in by_steps.items():
            r = table[k]
            w.writerow([k, steps, r["rmse_x100"], r["rmse_over_lerp"], r["pooled_jerk_over_gt"]])

fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
for k in range(4):
    xs = sorted(by_steps)
    axes[0].plot(xs, [float(by_steps[s][k]["rmse_over_lerp"]) for s in xs], "o-", label=f"K_x {k}")
    line = axes[1].plot(xs, [float(by_steps[s][k]["pooled_jerk_over_gt"]) for s in xs], "o-", label=f"K_x {k}")
    axes[1].axhline(float(oracle[k]["jerk_pooled_mean"]), color=line[0].get_color(), ls=":", lw=1)
axes[0].axhline(0.7, color="k", ls="--", lw=1, label="target at K_x 0")
axes[0].set_ylabel("ours' RMSE / lerp's")
axes[1].axhline(1.5, color="k", ls="--", lw=1, label="target 1.5")
axes[1].set_ylabel("pooled jerk / ground truth's (dotted: VAE floor)")
for ax in axes:
    ax.set_xlabel("RF training steps")
    ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{here}/jerk.png", dpi=110)

# ---- the shipped family per K_x -----------------------------------------------------------------------------------
final = {int(r["k_extra"]): {} for r in rows(f"{scale}/vs-4500.csv")}
for r in rows(f"{scale}/vs-4500.csv"):
    final[int(r["k_extra"])][r["row"]] = r
with open(f"{here}/summary.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["k_extra", "ours_rmse_x100", "lerp_rmse_x100", "baseline_rmse_x100", "ours_over_lerp",
                "ours_over_baseline", "ours_chamfer_x100", "lerp_chamfer_x100", "ours_jerk_over_gt",
                "vae_floor_rmse_x100", "vae_floor_jerk_over_gt", "vae750_floor_jerk_over_gt"])
    for k, r in sorted(final.items()):
        ours, lerp, base = r["v4500"], r["lerp"], r["baseline"]
        w.writerow([k, ours["rmse_x100"], lerp["rmse_x100"], base["rmse_x100"], ours["rmse_over_lerp"],
                    f"{float(ours['rmse_x100']) / float(base['rmse_x100']):.3f}", ours["chamfer_x100"],
                    lerp["chamfer_x100"], ours["pooled_jerk_over_gt"], f"{float(oracle[k]['rmse_mean']):.3f}",
                    f"{float(oracle[k]['jerk_pooled_mean']):.3f}", f"{float(oracle750[k]['jerk_pooled_mean']):.3f}"])
