"""Table 5 of vae-srra-nostk against the shipped VAE on each evaluation set, and against the corpus-arms' vae-srra and
the stk-vae experiment's vae-srras where their windows are the same ones (same names, and the shipped VAE scoring
each alike to 1e-3), paired by window, with 95 % intervals of
the mean difference resampled by object (all windows of a drawn object go together): results.csv, pairs.csv,
by-object.csv (held out) and results.png, from table5/<arm>/<set>/clips.parquet and the other experiments' files."""

import csv
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
EXP = HERE.parent
SETS = ["heldout", "real-val", "procedural-val", "rigged-val"]
ARM = "vae-srra-nostk"
# The other VAEs' table 5 files, by set (absent: not scored on that set).
OTHERS = {
    "vae-srra (corpus-arms)": {s: EXP / "2026-12-06-corpus-arms" / "table5" / "vae-srra" / s for s in SETS},
    "vae-srras (stk-vae)": {
        "heldout": EXP / "2026-12-07-stk-vae" / "table5-heldout",
        "real-val": EXP / "2026-12-07-stk-vae" / "table5-real-val",
        "procedural-val": EXP / "2026-12-07-stk-vae" / "table5-procedural-val",
    },
}


def object_uid(clip_id: str) -> str:
    return clip_id.split("_offset")[0]


def load(folder):
    """{(item, clip id): (rmse ×100, chamfer ×100)} of the shipped VAE and of the arm in `folder`."""
    t = pq.read_table(folder / "clips.parquet").to_pydict()
    by = {}
    for m, item, cid, rmse, ch in zip(t["method"], t["item"], t["clip_id"], t["rmse"], t["chamfer"]):
        by.setdefault(m, {})[(item, cid)] = (rmse * 100, ch * 100)
    return by["framewise"], by["framewise_b"]


def interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    return np.percentile(sums[draws].sum(axis=1) / counts[draws].sum(axis=1), [2.5, 97.5])


def main():
    rows, pairs, by_object = [], [], []
    for name in SETS:
        shipped, ours = load(HERE / "table5" / ARM / name)
        keys = sorted(ours)
        objects = np.array([object_uid(k[1]) for k in keys])
        a = np.array([shipped[k] for k in keys])
        b = np.array([ours[k] for k in keys])
        lo, hi = interval(b[:, 0] - a[:, 0], objects)
        rows.append({
            "set": name, "windows": len(keys), "objects": len(np.unique(objects)),
            "shipped_rmse": round(a[:, 0].mean(), 3), "shipped_chamfer": round(a[:, 1].mean(), 3),
            "rmse": round(b[:, 0].mean(), 3), "chamfer": round(b[:, 1].mean(), 3),
            "minus_shipped": round((b[:, 0] - a[:, 0]).mean(), 3), "lo": round(lo, 3), "hi": round(hi, 3),
        })
        for other, folders in OTHERS.items():
            folder = folders.get(name)
            if folder is None or not (folder / "clips.parquet").exists():
                continue
            their_shipped, theirs = load(folder)
            if sorted(theirs) != keys:
                continue  # other windows: no pairing
            if any(abs(their_shipped[k][0] - shipped[k][0]) > 1e-3 for k in keys):
                continue  # the same window names over other clips (a store rebuilt since): no pairing
            c = np.array([theirs[k] for k in keys])
            diff = b[:, 0] - c[:, 0]
            lo, hi = interval(diff, objects)
            pairs.append({"set": name, "comparison": f"{ARM} - {other}", "windows": len(keys),
                          "objects": len(np.unique(objects)), "other_rmse": round(c[:, 0].mean(), 3),
                          "rmse": round(b[:, 0].mean(), 3), "diff_rmse": round(diff.mean(), 3),
                          "lo": round(lo, 3), "hi": round(hi, 3)})
            if name == "heldout":
                for u in np.unique(objects):
                    g = objects == u
                    by_object.append({"object": u, "windows": int(g.sum()), "other": other,
                                      "shipped": round(a[g, 0].mean(), 3), "other_rmse": round(c[g, 0].mean(), 3),
                                      "rmse": round(b[g, 0].mean(), 3)})
    for path, table in [(HERE / "results.csv", rows), (HERE / "pairs.csv", pairs), (HERE / "by-object.csv", by_object)]:
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(table[0]))
            w.writeheader()
            w.writerows(table)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    width = 0.2
    x = np.arange(len(SETS))
    ax.bar(x - 1.5 * width, [r["shipped_rmse"] for r in rows], width, label="shipped VAE", color="grey")
    for i, (other, color) in enumerate([("vae-srra (corpus-arms)", "tab:blue"), ("vae-srras (stk-vae)", "tab:red")]):
        vals = [next((p["other_rmse"] for p in pairs if p["set"] == s and other in p["comparison"]), 0) for s in SETS]
        ax.bar(x + (i - 0.5) * width, vals, width, label=other, color=color)
    ax.bar(x + 1.5 * width, [r["rmse"] for r in rows], width, label=ARM, color="tab:green")
    ax.set_xticks(x, SETS)
    ax.set_ylabel("table 5 RMSE ×100 (posterior mean)")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "results.png", dpi=120)
    for r in rows + pairs:
        print(r)


if __name__ == "__main__":
    main()
