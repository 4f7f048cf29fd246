"""Draws sets.png: RMSE ×100 against K_x on the three evaluation sets (procedural validation, real validation,
held-out real), for the shipped RF, its 1,000-step continuation on procedural clips and its 1,000-step fine-tune on
procedural + real clips, with lerp."""
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = Path(__file__).resolve().parent
sets = [("procedural-vs-shipped.csv", "procedural validation (300 windows)"),
        ("realval-vs-shipped.csv", "real validation split (50 windows)"),
        ("heldout-vs-shipped.csv", "held-out real clips (189 windows)")]
rows = {"shipped": ("shipped RF", "o-"), "proc_ft": ("+ 1,000 steps procedural", "s-"),
        "both_ft": ("+ 1,000 steps procedural + real (--init)", "^-"), "lerp": ("lerp", "k--")}
fig, axes = plt.subplots(1, 3, figsize=(13, 4))
for ax, (name, title) in zip(axes, sets):
    table = list(csv.DictReader(open(here / name)))
    for key, (label, style) in rows.items():
        pts = sorted((int(r["k_extra"]), float(r["rmse_x100"])) for r in table if r["row"] == key)
        ax.plot([k for k, _ in pts], [v for _, v in pts], style, label=label)
    ax.set(title=title, xlabel="K_x", ylabel="RMSE ×100", xticks=range(4))
axes[0].legend(fontsize=7)
fig.tight_layout()
fig.savefig(here / "sets.png", dpi=110)
