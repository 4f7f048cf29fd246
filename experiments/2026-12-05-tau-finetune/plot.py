"""Draws rmse-jerk.png from vs-shipped-3seeds.csv: RMSE ×100 and pooled jerk ÷ GT against K_x for the shipped RF
and its two 1,000-step continuations (uniform and logit-normal τ), with lerp and the Baseline for scale."""
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

here = Path(__file__).resolve().parent
rows = list(csv.DictReader(open(here / "vs-shipped-3seeds.csv")))
names = {"shipped": "shipped RF (9,000 steps)", "uniform": "+ 1,000 steps, uniform τ",
         "logit": "+ 1,000 steps, logit-normal τ", "lerp": "lerp", "baseline": "Baseline"}
fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
for i, (key, label) in enumerate(names.items()):
    sel = [r for r in rows if r["row"] == key]
    kx = [int(r["k_extra"]) for r in sel]
    style = "--" if key in ("lerp", "baseline") else "-o"
    a.plot(kx, [float(r["rmse_x100"]) for r in sel], style, color=f"C{i}", label=label)
    if key != "lerp":
        b.plot(kx, [float(r["pooled_jerk_over_gt"]) for r in sel], style, color=f"C{i}", label=label)
b.axhline(1.5, color="grey", lw=0.8, ls=":", label="target 1.5 × GT")
a.set(xlabel="K_x", ylabel="RMSE ×100 (300 windows)", xticks=range(4))
b.set(xlabel="K_x", ylabel="pooled jerk ÷ ground truth", xticks=range(4))
a.legend(fontsize=7)
b.legend(fontsize=7)
fig.tight_layout()
fig.savefig(here / "rmse-jerk.png", dpi=120)
