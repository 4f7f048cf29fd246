"""sets.png: RMSE x100 against K_x of every row of the three comparison CSVs (held out, real validation,
procedural), one panel per set, from the files compare.py wrote beside this script."""

import csv
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

HERE = pathlib.Path(__file__).resolve().parent
SETS = [
    ("heldout-vs-shipped.csv", "held-out real characters (63 windows, 6 objects, 3 seeds)"),
    ("real-val-vs-shipped.csv", "real validation split (50 windows, 1 seed)"),
    ("procedural-vs-shipped.csv", "procedural validation (100 clips, 3 seeds)"),
]
STYLE = {
    "shipped": ("tab:grey", "shipped ours (procedural)"),
    "ours_real": ("tab:red", "ours, real-motion family"),
    "lerp": ("black", "vertex lerp"),
    "latent_lerp": ("tab:blue", "latent lerp (its VAE)"),
    "vae_oracle": ("tab:green", "its VAE's floor"),
    "baseline_shipped": ("tab:olive", "shipped Baseline"),
}


def main():
    fig, axes = plt.subplots(1, len(SETS), figsize=(4.2 * len(SETS), 3.6))
    for ax, (name, title) in zip(axes, SETS):
        path = HERE / name
        if not path.exists():
            ax.set_visible(False)
            continue
        rows = list(csv.DictReader(path.open()))
        for label in dict.fromkeys(r["row"] for r in rows):
            mine = [r for r in rows if r["row"] == label]
            color, text = STYLE.get(label, (None, label))
            ax.plot(
                [int(r["k_extra"]) for r in mine],
                [float(r["rmse_x100"]) for r in mine],
                marker="o",
                color=color,
                label=text,
                ls="--" if label in ("lerp", "latent_lerp", "vae_oracle") else "-",
            )
        ax.set_title(title, fontsize=8)
        ax.set_xlabel("extra keyframes K_x")
        ax.set_ylabel("RMSE ×100 (non-keyframes)")
        ax.set_xticks(range(4))
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(HERE / "sets.png", dpi=120)


if __name__ == "__main__":
    main()
