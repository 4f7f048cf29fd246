"""RMSE x100 against K_x for the rows of summary.csv (100 clips x 3 seeds) and the anchored row of
anchor-vs-firstlast.csv (seed 42 only), written to rmse_vs_kx.png. usage: python3 plot.py"""
import csv
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

def rows(path):
    out = {}
    for r in csv.DictReader(open(path)):
        out.setdefault(r["row"], []).append((int(r["k_extra"]), float(r["rmse_x100"])))
    return out

three = rows("summary.csv")
anchored = rows("anchor-vs-firstlast.csv")["anchored"]
labels = {"ours": "shipped RF before (paper's keyframe draw)", "firstlast": "first-last keyframes (now shipped)",
          "lerp": "lerp", "baseline": "Baseline (replacement)"}
fig, ax = plt.subplots(figsize=(6, 4))
for key, label in labels.items():
    k, v = zip(*sorted(three[key]))
    ax.plot(k, v, marker="o", label=f"{label}, 3 seeds")
k, v = zip(*sorted(anchored))
ax.plot(k, v, marker="s", linestyle="--", label="anchored (step 1,081), seed 42")
ax.set_xlabel("K_x (extra keyframes)")
ax.set_ylabel("RMSE x100 (non-keyframes)")
ax.set_xticks([0, 1, 2, 3])
ax.legend(fontsize=7)
ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig("rmse_vs_kx.png", dpi=120)
