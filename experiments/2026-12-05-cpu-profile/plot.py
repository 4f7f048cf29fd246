#!/usr/bin/env python3
"""where.png: per network and thread count, ours' step split by kind of work (share-t{1,2}.csv scaled to ours'
median step time from summary.csv) beside PyTorch's median step time."""
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import summarise

here = os.path.dirname(os.path.abspath(__file__))
summary = list(csv.DictReader(open(f"{here}/summary.csv")))
PROF = dict(summarise.NETS)  # the bench log's network name -> the profile's
GROUPS = [("matrix products (gemm)", ("gemm microkernel", "gemm packing and dispatch")),
          ("burn-flex realignment copy", ("burn-flex realignment copy",)),
          ("softmax's scalar exp", ("libm exp",)),
          ("element-wise, copies, attention op, rest", ())]
fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), sharey=False)
for ax, threads in zip(axes, (1, 2)):
    share = [r for r in csv.DictReader(open(f"{here}/share-t{threads}.csv")) if not r["category"].startswith("(also)")]
    rows = [r for r in summary if int(r["threads"]) == threads]
    for i, r in enumerate(rows):
        net = PROF[r["network"]]
        total = next(int(s["samples"]) for s in share if s["network"] == net and s["category"] == "all timed samples")
        ours = float(r["ours_ms"]) / 1e3
        bottom = 0.0
        used = 0
        for j, (label, prefixes) in enumerate(GROUPS):
            if prefixes:
                k = sum(int(s["samples"]) for s in share if s["network"] == net
                        and any(s["category"].startswith(p) for p in prefixes))
            else:
                k = total - used
            used += k
            h = ours * k / total
            ax.bar(2 * i, h, bottom=bottom, color=f"C{j}", label=label if i == 0 else None)
            bottom += h
        ax.bar(2 * i + 0.8, float(r["pytorch_ms"]) / 1e3, color="grey", label="PyTorch (whole step)" if i == 0 else None)
        ax.text(2 * i + 0.4, max(ours, float(r["pytorch_ms"]) / 1e3) * 1.02, f"{float(r['ratio_median']):.2f}×",
                ha="center", fontsize=8)
    ax.set_xticks([2 * i + 0.4 for i in range(len(rows))])
    ax.set_xticklabels(["RF fwd+bwd", "frame-wise VAE", "DyMeshVAE"])
    ax.set_ylabel("seconds per step (ours split by the profile's shares)")
    ax.set_title(f"{threads} thread{'s' if threads > 1 else ''}: ours (stacked) and PyTorch (grey); ours/PyTorch above")
    ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{here}/where.png", dpi=110)
