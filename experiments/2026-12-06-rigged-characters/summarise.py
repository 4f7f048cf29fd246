"""Table 5 of the two VAEs on each evaluation set, paired by window, with 95 % intervals of the difference resampled
by object (all windows of a drawn object go together): results.csv and results.png from table5/*/clips.parquet."""

import csv
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
SETS = ["heldout", "real-val", "procedural-val", "rigged-val"]
ROWS = {"framewise": "shipped (procedural)", "framewise_b": "procedural + rigged"}


def object_uid(clip_id: str) -> str:
    return clip_id.split("_offset")[0]


def load(name):
    t = pq.read_table(HERE / "table5" / name / "clips.parquet").to_pydict()
    by = {}
    for m, item, cid, rmse, ch in zip(t["method"], t["item"], t["clip_id"], t["rmse"], t["chamfer"]):
        by.setdefault(m, {})[(item, cid)] = (rmse, ch)
    keys = sorted(by["framewise"])
    assert keys == sorted(by["framewise_b"]), name
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
    for name in SETS:
        a, b, objects = load(name)
        d = b[:, 0] - a[:, 0]
        lo, hi = by_object_interval(d, objects)
        out.append(
            {
                "set": name,
                "windows": len(d),
                "objects": len(np.unique(objects)),
                "rmse_x100_shipped": round(a[:, 0].mean(), 3),
                "rmse_x100_rigged": round(b[:, 0].mean(), 3),
                "chamfer_x100_shipped": round(a[:, 1].mean(), 3),
                "chamfer_x100_rigged": round(b[:, 1].mean(), 3),
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
    fig, ax = plt.subplots(figsize=(7, 3.2))
    x = np.arange(len(out))
    ax.bar(x - 0.2, [r["rmse_x100_shipped"] for r in out], 0.4, label=ROWS["framewise"], color="grey")
    ax.bar(x + 0.2, [r["rmse_x100_rigged"] for r in out], 0.4, label=ROWS["framewise_b"], color="indianred")
    ax.set_xticks(x, [f"{r['set']}\n({r['windows']} windows, {r['objects']} objects)" for r in out], fontsize=8)
    ax.set_ylabel("table 5 RMSE ×100")
    ax.set_title("Frame-wise VAE, small preset, 2,000 steps: reconstruction by training data")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "results.png", dpi=120)
    for r in out:
        print(r)


if __name__ == "__main__":
    main()
