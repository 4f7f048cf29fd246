"""Where the frame-wise VAE's reconstruction error lies, from table 5's per-vertex files (`eval run --per-vertex`,
docs/evaluation.md "Per-vertex errors"): for each set and VAE,

- features.csv: the vertices pooled over the set's windows, cut into quintiles of each feature (displacement,
  radius, token_distance, gap; tied edges merge two quintiles into one bin; gap's null — no other part within
  reach — is its own bin), with each bin's mean
  per-vertex RMSE ×100 and its share of the set's squared error (the share RMSE² carries), and the bin's edges;
- correlations.csv: Spearman rank correlation of per-vertex RMSE with each feature, pooled and the median over
  windows (within a window, which vertices err most);
- windows.csv: per window its RMSE ×100 (table 5's (E4)), vertices, the share of squared error in its worst 5 % of
  vertices, its mean displacement, its object and source;
- motion.csv: per set and VAE, the windows split at their median mean displacement: each half's mean RMSE ×100
  and share of squared error, and the Spearman correlation of window RMSE with mean displacement;
- tokens.csv: the real-trained VAE's weights told P = 128 (as trained), 256 and 512 tokens at inference, held out:
  mean RMSE ×100 and the difference to P = 128 with a 95 % interval resampled by object;
- maps/*.png: held-out windows drawn as their frame-0 vertices seen from the front and the side, coloured by
  per-vertex RMSE on one scale for both VAEs.

  python3 experiments/2026-12-08-vae-error-maps/analyse.py

numpy, pyarrow, matplotlib."""

import csv
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
SETS = ["heldout", "procedural-val", "train-val"]
LABELS = {"framewise": "shipped", "framewise_b": "real-trained"}
FEATURES = ["displacement", "radius", "token_distance", "gap"]
BINS = 5


def object_uid(clip_id):
    return clip_id.split("_offset")[0]


def source(clip_id):
    if clip_id.startswith("rigged-"):
        return "rigged"
    if clip_id.startswith("synth-"):
        return "procedural"
    return "real"


def load(folder):
    t = pq.read_table(folder / "vertices.parquet").to_pydict()
    return {k: np.asarray(v, dtype=object if k in ("method", "clip_id") else None) for k, v in t.items()}


def ranks(x):
    order = np.argsort(x, kind="stable")
    r = np.empty(len(x))
    r[order] = np.arange(len(x))
    return r


def spearman(a, b):
    keep = np.isfinite(a) & np.isfinite(b)
    if keep.sum() < 3:
        return float("nan")
    ra, rb = ranks(a[keep]), ranks(b[keep])
    if ra.std() == 0 or rb.std() == 0:
        return float("nan")
    return float(np.corrcoef(ra, rb)[0, 1])


def column(t, name, sel):
    return np.array([np.nan if v is None else v for v in t[name][sel]], dtype=float)


def write(path, table):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)


def main():
    features, correlations, windows = [], [], []
    tables = {}
    for name in SETS:
        folder = HERE / "table5" / name
        if not (folder / "vertices.parquet").exists():
            continue
        t = load(folder)
        tables[name] = t
        for method, label in LABELS.items():
            sel = t["method"] == method
            if not sel.any():
                continue
            rmse = column(t, "rmse", sel)
            total = np.sum(rmse**2)
            for feat in FEATURES:
                x = column(t, feat, sel)
                finite = np.isfinite(x)
                # Quintile edges, merged where values tie (a token vertex is 0 from its token).
                edges = np.unique(np.quantile(x[finite], np.linspace(0, 1, BINS + 1))) if finite.any() else []
                last = len(edges) - 2
                cuts = [(f"bin{i + 1}", (x >= edges[i]) & ((x < edges[i + 1]) if i < last else (x <= edges[i + 1])),
                         edges[i], edges[i + 1]) for i in range(len(edges) - 1)]
                if (~finite).any():
                    cuts.append(("none", ~finite, float("nan"), float("nan")))
                for b, m, lo, hi in cuts:
                    if not m.any():
                        continue
                    features.append({
                        "set": name, "vae": label, "feature": feat, "bin": b,
                        "low": f"{lo:.4f}", "high": f"{hi:.4f}", "vertices": int(m.sum()),
                        "rmse_x100": f"{100 * np.sqrt(np.mean(rmse[m] ** 2)):.3f}",
                        "share_of_squared_error": f"{np.sum(rmse[m] ** 2) / total:.4f}",
                    })
                items = t["item"][sel]
                within = [spearman(rmse[items == i], x[items == i]) for i in np.unique(items)]
                correlations.append({
                    "set": name, "vae": label, "feature": feat,
                    "spearman_pooled": f"{spearman(rmse, x):.3f}",
                    "spearman_within_window_median": f"{np.nanmedian(within):.3f}",
                    "windows": len(within),
                })
            ids = t["clip_id"][sel]
            items = t["item"][sel]
            disp = column(t, "displacement", sel)
            for i in np.unique(items):
                m = items == i
                r = np.sort(rmse[m])[::-1]
                worst = max(1, int(np.ceil(0.05 * len(r))))
                windows.append({
                    "set": name, "vae": label, "item": int(i), "clip_id": ids[m][0],
                    "object": object_uid(ids[m][0]), "source": source(ids[m][0]), "vertices": int(m.sum()),
                    "rmse_x100": f"{100 * np.sqrt(np.mean(r ** 2)):.3f}",
                    "worst5pct_share": f"{np.sum(r[:worst] ** 2) / max(np.sum(r ** 2), 1e-30):.3f}",
                    "mean_displacement": f"{disp[m].mean():.4f}",
                })
    if not features:
        raise SystemExit("no table5/*/vertices.parquet: run run.sh first")
    write(HERE / "features.csv", features)
    write(HERE / "correlations.csv", correlations)
    write(HERE / "windows.csv", windows)
    motion(windows)
    tokens()
    maps(tables.get("heldout"))


def motion(windows):
    rows = []
    for name in SETS:
        for label in LABELS.values():
            sel = [w for w in windows if w["set"] == name and w["vae"] == label]
            if not sel:
                continue
            e = np.array([float(w["rmse_x100"]) for w in sel])
            d = np.array([float(w["mean_displacement"]) for w in sel])
            big = d > np.median(d)
            rows.append({
                "set": name, "vae": label, "windows": len(sel), "median_displacement": f"{np.median(d):.4f}",
                "rmse_x100_calmer_half": f"{e[~big].mean():.3f}", "rmse_x100_moving_half": f"{e[big].mean():.3f}",
                "moving_half_share_of_squared_error": f"{np.sum(e[big] ** 2) / np.sum(e ** 2):.3f}",
                "spearman_rmse_displacement": f"{spearman(e, d):.3f}",
            })
    write(HERE / "motion.csv", rows)


def window_rmse(folder, method):
    t = pq.read_table(folder / "clips.parquet").to_pydict()
    return {(i, c): r * 100 for m, i, c, r in zip(t["method"], t["item"], t["clip_id"], t["rmse"]) if m == method}


def interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    return np.percentile(sums[draws].sum(axis=1) / counts[draws].sum(axis=1), [2.5, 97.5])


def tokens():
    folder = HERE / "table5" / "heldout-tokens"
    if not (folder / "clips.parquet").exists():
        return
    base = window_rmse(HERE / "table5" / "heldout", "framewise_b")
    keys = sorted(base)
    objects = np.array([object_uid(c) for _, c in keys])
    b = np.array([base[k] for k in keys])
    rows = [{"tokens": 128, "rmse_x100": f"{b.mean():.3f}", "minus_p128": "0", "ci_low": "", "ci_high": ""}]
    for p, method in [(256, "framewise"), (512, "framewise_b")]:
        other = window_rmse(folder, method)
        if sorted(other) != keys:
            raise SystemExit(f"{folder}: windows differ from table5/heldout")
        o = np.array([other[k] for k in keys])
        lo, hi = interval(o - b, objects)
        rows.append({"tokens": p, "rmse_x100": f"{o.mean():.3f}", "minus_p128": f"{(o - b).mean():+.3f}",
                     "ci_low": f"{lo:+.3f}", "ci_high": f"{hi:+.3f}"})
    write(HERE / "tokens.csv", rows)


def maps(t):
    """One picture per held-out object: its worst window for the shipped VAE, both VAEs, front (x, y) and side
    (z, y) views of frame 0, colour = per-vertex RMSE ×100 on one scale."""
    if t is None:
        return
    out = HERE / "maps"
    out.mkdir(exist_ok=True)
    shipped = t["method"] == "framewise"
    worst = {}
    for i in np.unique(t["item"][shipped]):
        m = shipped & (t["item"] == i)
        cid = t["clip_id"][m][0]
        e = np.sqrt(np.mean(column(t, "rmse", m) ** 2))
        obj = object_uid(cid)
        if obj not in worst or e > worst[obj][1]:
            worst[obj] = (i, e, cid)
    for obj, (i, _, cid) in sorted(worst.items()):
        panels = [(label, (t["method"] == method) & (t["item"] == i)) for method, label in LABELS.items()]
        panels = [(label, m) for label, m in panels if m.any()]
        vmax = max(np.quantile(100 * column(t, "rmse", m), 0.99) for _, m in panels)
        fig, axes = plt.subplots(1, 2 * len(panels), figsize=(4 * 2 * len(panels), 4.4))
        for k, (label, m) in enumerate(panels):
            x, y, z = (column(t, c, m) for c in "xyz")
            e = 100 * column(t, "rmse", m)
            order = np.argsort(e)
            for j, (h, view) in enumerate([(x, "front (x, y)"), (z, "side (z, y)")]):
                ax = axes[2 * k + j]
                sc = ax.scatter(h[order], y[order], c=e[order], s=3, cmap="inferno", vmin=0, vmax=vmax)
                ax.set_aspect("equal")
                ax.set_xticks([])
                ax.set_yticks([])
                ax.set_title(f"{label}: RMSE×100 {np.sqrt(np.mean(e ** 2)):.1f}\n{view}", fontsize=9)
        fig.colorbar(sc, ax=axes, shrink=0.8, label="per-vertex RMSE ×100")
        fig.suptitle(cid, fontsize=9)
        fig.savefig(out / f"{obj}.png", dpi=80)
        plt.close(fig)


if __name__ == "__main__":
    main()
