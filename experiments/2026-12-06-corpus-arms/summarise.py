"""Table 5 of every training-data arm against the shipped VAE on each evaluation set, paired by window, with 95 %
intervals of the difference resampled by object (all windows of a drawn object go together); results.csv and
results.png from table5/<arm>/<set>/clips.parquet, curve.png (held-out error against training objects), and
pairs.csv (arm against arm: augmentation, the real corpus, the whole corpus)."""

import csv
import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
SETS = ["heldout", "real-val", "procedural-val", "rigged-val"]
ARMS = json.loads((HERE / "arms.json").read_text())


def object_uid(clip_id: str) -> str:
    return clip_id.split("_offset")[0]


def load(arm, name):
    path = HERE / "table5" / arm / name / "clips.parquet"
    if not path.exists():
        return None
    t = pq.read_table(path).to_pydict()
    by = {}
    for m, item, cid, rmse, ch in zip(t["method"], t["item"], t["clip_id"], t["rmse"], t["chamfer"]):
        by.setdefault(m, {})[(item, cid)] = (rmse, ch)
    keys = sorted(by["framewise"])
    assert keys == sorted(by["framewise_b"]), (arm, name)
    a = np.array([by["framewise"][k] for k in keys]) * 100
    b = np.array([by["framewise_b"][k] for k in keys]) * 100
    objects = np.array([object_uid(k[1]) for k in keys])
    return a, b, objects


def by_object_interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    means = sums[draws].sum(axis=1) / counts[draws].sum(axis=1)
    return np.percentile(means, [2.5, 97.5])


def main():
    out = []
    for arm in ARMS:
        for name in SETS:
            got = load(arm["name"], name)
            if got is None:
                continue
            a, b, objects = got
            d = b[:, 0] - a[:, 0]
            lo, hi = by_object_interval(d, objects)
            out.append(
                {
                    "arm": arm["name"],
                    "train_objects": arm["train_objects"],
                    "set": name,
                    "windows": len(d),
                    "objects": len(np.unique(objects)),
                    "rmse_x100_shipped": round(a[:, 0].mean(), 3),
                    "rmse_x100_arm": round(b[:, 0].mean(), 3),
                    "chamfer_x100_shipped": round(a[:, 1].mean(), 3),
                    "chamfer_x100_arm": round(b[:, 1].mean(), 3),
                    "rmse_diff": round(d.mean(), 3),
                    "rmse_diff_lo": round(lo, 3),
                    "rmse_diff_hi": round(hi, 3),
                    "ratio": round(b[:, 0].mean() / a[:, 0].mean(), 3),
                }
            )
    with open(HERE / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(out[0]))
        w.writeheader()
        w.writerows(out)

    fig, ax = plt.subplots(figsize=(8, 3.4))
    x = np.arange(len(SETS))
    width = 0.8 / (len(ARMS) + 1)
    shipped = {r["set"]: r["rmse_x100_shipped"] for r in out}
    ax.bar(x - 0.4 + width / 2, [shipped.get(s, np.nan) for s in SETS], width, label="shipped (procedural)", color="grey")
    for i, arm in enumerate(ARMS, start=1):
        vals = {r["set"]: r["rmse_x100_arm"] for r in out if r["arm"] == arm["name"]}
        ax.bar(x - 0.4 + width * (i + 0.5), [vals.get(s, np.nan) for s in SETS], width, label=arm["label"])
    ax.set_xticks(x, SETS, fontsize=8)
    ax.set_ylabel("table 5 RMSE ×100")
    ax.set_title("Frame-wise VAE, small preset, 2,000 steps, by training data")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(HERE / "results.png", dpi=120)

    fig, ax = plt.subplots(figsize=(5, 3.4))
    held = [r for r in out if r["set"] == "heldout"]
    pts = [(1590, held[0]["rmse_x100_shipped"], "shipped")] + [
        (r["train_objects"], r["rmse_x100_arm"], r["arm"]) for r in held
    ]
    for n, e, label in pts:
        ax.scatter(n, e)
        ax.annotate(label, (n, e), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_xlabel("objects in the training split")
    ax.set_ylabel("held-out table 5 RMSE ×100")
    ax.axhline(4.6, ls="--", c="k", lw=0.8)
    ax.text(pts[0][0], 4.7, "2× target (4.6)", fontsize=7)
    fig.tight_layout()
    fig.savefig(HERE / "curve.png", dpi=120)
    for r in out:
        print(r)
    pairs(out)


# Arm against arm on the same windows: what augmentation and each added corpus buy.
PAIRS = [("vae-sra", "vae-sr"), ("vae-srra", "vae-srr"), ("vae-srr", "vae-sr"), ("vae-tc", "vae-srr")]


def pairs(out):
    rows = []
    for arm, base in PAIRS:
        for name in SETS:
            got, ref = load(arm, name), load(base, name)
            if got is None or ref is None:
                continue
            d = got[1][:, 0] - ref[1][:, 0]
            lo, hi = by_object_interval(d, got[2])
            rows.append(
                {
                    "arm": arm,
                    "against": base,
                    "set": name,
                    "rmse_x100_against": round(ref[1][:, 0].mean(), 3),
                    "rmse_x100_arm": round(got[1][:, 0].mean(), 3),
                    "rmse_diff": round(d.mean(), 3),
                    "rmse_diff_lo": round(lo, 3),
                    "rmse_diff_hi": round(hi, 3),
                }
            )
    with open(HERE / "pairs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
