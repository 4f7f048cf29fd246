"""RMSE x100 against K_x on the three evaluation sets (real validation, held-out real, procedural validation) for
the rows of real-val.csv, heldout.csv and procedural-val.csv, one panel each, written to rmse_vs_kx.png.
usage: python3 plot.py"""
import csv
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

labels = {"procedural": "RF trained on procedural clips (shipped, 1,500 steps)",
          "procedural1000": "RF trained on procedural clips, step 1,000",
          "real1000": "RF trained on real clips, step 1,000",
          "both1000": "RF trained on procedural + real clips, step 1,000",
          "baseline": "replacement Baseline (shipped, procedural)",
          "latentlerp": "latent lerp (the VAE on interpolated keyframe latents)", "lerp": "lerp"}
panels = [("real-val.csv", "real validation (50 windows)"), ("heldout.csv", "held-out real (63 windows)"),
          ("procedural-val.csv", "procedural validation (50 windows)")]
fig, axes = plt.subplots(1, 3, figsize=(13, 4))
for ax, (path, title) in zip(axes, panels):
    rows = {}
    for r in csv.DictReader(open(path)):
        rows.setdefault(r["row"], []).append((int(r["k_extra"]), float(r["rmse_x100"])))
    for key, label in labels.items():
        if key in rows:
            k, v = zip(*sorted(rows[key]))
            ax.plot(k, v, marker="o", label=label)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("K_x (extra keyframes)")
    ax.set_ylabel("RMSE x100 (non-keyframes)")
    ax.set_xticks([0, 1, 2, 3])
    ax.grid(alpha=0.3)
axes[0].legend(fontsize=7)
fig.tight_layout()
fig.savefig("rmse_vs_kx.png", dpi=120)

# summary.csv: the three tables in one file, with the evaluation set as the first column
with open("summary.csv", "w", newline="") as out:
    writer = None
    for path, _ in panels:
        for r in csv.DictReader(open(path)):
            if writer is None:
                writer = csv.DictWriter(out, ["set"] + list(r))
                writer.writeheader()
            writer.writerow({"set": path[:-4], **r})
