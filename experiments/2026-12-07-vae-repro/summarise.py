"""Table 5 of the separating arm (vae-srra-nostk-rig5) against the shipped VAE, and paired window by window with the
corpus-arms' vae-srra and the stk-control's vae-srra-nostk on the held-out store and the procedural validation
clips (the same windows: same names, the shipped VAE scoring each alike to 1e-3), with 95 % intervals of the mean
difference resampled by object: results.csv, pairs.csv, by-object.csv (held out), results.png, from
table5/<arm>/<set>/clips.parquet and the other experiments' files. numpy, pyarrow, matplotlib."""

import csv
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
EXP = HERE.parent
SETS = ["heldout", "procedural-val"]
ARM = "vae-srra-nostk-rig5"
OTHERS = {
    "vae-srra (corpus-arms)": EXP / "2026-12-06-corpus-arms" / "table5" / "vae-srra",
    "vae-srra-nostk (stk-control)": EXP / "2026-12-07-stk-control" / "table5" / "vae-srra-nostk",
}
COLOURS = {"vae-srra (corpus-arms)": "tab:blue", "vae-srra-nostk (stk-control)": "tab:red"}


def object_uid(clip_id):
    return clip_id.split("_offset")[0]


def load(folder):
    """{(item, clip id): RMSE ×100} of the shipped VAE and of the other VAE in `folder`."""
    t = pq.read_table(folder / "clips.parquet").to_pydict()
    by = {}
    for m, item, cid, rmse in zip(t["method"], t["item"], t["clip_id"], t["rmse"]):
        by.setdefault(m, {})[(item, cid)] = rmse * 100
    return by["framewise"], by["framewise_b"]


def interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    return np.percentile(sums[draws].sum(axis=1) / counts[draws].sum(axis=1), [2.5, 97.5])


def write(path, table):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)


def main():
    rows, pairs, by_object = [], [], []
    for name in SETS:
        shipped, ours = load(HERE / "table5" / ARM / name)
        keys = sorted(ours)
        objects = np.array([object_uid(k[1]) for k in keys])
        a = np.array([shipped[k] for k in keys])
        b = np.array([ours[k] for k in keys])
        lo, hi = interval(b - a, objects)
        rows.append({"set": name, "windows": len(keys), "objects": len(np.unique(objects)),
                     "shipped_rmse": round(a.mean(), 3), "rmse": round(b.mean(), 3),
                     "minus_shipped": round((b - a).mean(), 3), "lo": round(lo, 3), "hi": round(hi, 3)})
        for other, root in OTHERS.items():
            their_shipped, theirs = load(root / name)
            if sorted(theirs) != keys or any(abs(their_shipped[k] - shipped[k]) > 1e-3 for k in keys):
                raise SystemExit(f"{name}: {other} scored other windows; no pairing")
            c = np.array([theirs[k] for k in keys])
            lo, hi = interval(b - c, objects)
            pairs.append({"set": name, "comparison": f"{ARM} - {other}", "windows": len(keys),
                          "objects": len(np.unique(objects)), "other_rmse": round(c.mean(), 3),
                          "rmse": round(b.mean(), 3), "diff_rmse": round((b - c).mean(), 3),
                          "lo": round(lo, 3), "hi": round(hi, 3)})
            if name == "heldout":
                for u in np.unique(objects):
                    g = objects == u
                    by_object.append({"object": u, "windows": int(g.sum()), "other": other,
                                      "shipped": round(a[g].mean(), 3), "other_rmse": round(c[g].mean(), 3),
                                      "rmse": round(b[g].mean(), 3)})
    write(HERE / "results.csv", rows)
    write(HERE / "pairs.csv", pairs)
    write(HERE / "by-object.csv", by_object)
    fig, ax = plt.subplots(figsize=(7, 3.4))
    width, x = 0.2, np.arange(len(SETS))
    ax.bar(x - 1.5 * width, [r["shipped_rmse"] for r in rows], width, label="shipped VAE", color="grey")
    for i, other in enumerate(OTHERS):
        vals = [next(p["other_rmse"] for p in pairs if p["set"] == s and other in p["comparison"]) for s in SETS]
        ax.bar(x + (i - 0.5) * width, vals, width, label=other, color=COLOURS[other])
    ax.bar(x + 1.5 * width, [r["rmse"] for r in rows], width, label=ARM + " (a5fd204 rigged clips)",
           color="tab:green")
    ax.set_xticks(x, SETS)
    ax.set_ylabel("table 5 RMSE ×100 (posterior mean)")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "results.png", dpi=120)
    for r in rows + pairs:
        print(r)


if __name__ == "__main__":
    main()
