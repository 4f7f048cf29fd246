#!/usr/bin/env python3
"""Table 1 of the small models: merge the `eval run` summaries (one per keyframe-latent choice) into one CSV with a
`keyframe_latents` column, the ratios the targets name, and one RMSE-vs-K_x plot.

Usage: python3 combine.py OUT_DIR (this folder: `.`) LABEL=EVAL_DIR [LABEL=EVAL_DIR ...]
LABEL is `mean` or `sample` (the `--posterior` the run used); every EVAL_DIR must hold the same manifest.json.
Writes OUT_DIR/summary.csv, OUT_DIR/ratios.csv and OUT_DIR/rmse_vs_kx.png.
"""
import csv
import hashlib
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(out, pairs):
    os.makedirs(out, exist_ok=True)
    rows, digests = [], set()
    for pair in pairs:
        label, folder = pair.split("=", 1)
        with open(os.path.join(folder, "manifest.json"), "rb") as f:
            digests.add(hashlib.sha256(f.read()).hexdigest())
        with open(os.path.join(folder, "summary.csv")) as f:
            for r in csv.DictReader(f):
                # Vertex-space methods do not read latents: keep one copy of each.
                if r["method"] in ("lerp", "static_nearest") and any(
                    (x["method"], x["k_extra"]) == (r["method"], r["k_extra"]) for x in rows
                ):
                    continue
                r = {"keyframe_latents": label if r["method"] not in ("lerp", "static_nearest") else "", **r}
                r.pop("data", None)
                rows.append(r)
    if len(digests) != 1:
        sys.exit("the evaluations used different manifests")
    fields = list(rows[0].keys())
    with open(os.path.join(out, "summary.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)

    def value(method, latents, k, col="rmse_mean"):
        for r in rows:
            if r["method"] == method and r["keyframe_latents"] == latents and r["k_extra"] == str(k):
                return float(r[col])
        return None

    ratios = []
    for latents in ("mean", "sample"):
        for k in range(4):
            ours, base, lerp = value("keyframe_rf", latents, k), value("replacement_rf", latents, k), value("lerp", "", k)
            if ours is None:
                continue
            ratios.append({
                "keyframe_latents": latents,
                "k_extra": k,
                "ours_rmse": ours,
                "ours_over_lerp": ours / lerp,
                "ours_over_baseline": ours / base if base else "",
                "ours_jerk_over_gt": value("keyframe_rf", latents, k, "jerk_ratio_mean"),
                "ours_chamfer": value("keyframe_rf", latents, k, "chamfer_mean"),
            })
    with open(os.path.join(out, "ratios.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(ratios[0].keys()))
        w.writeheader()
        w.writerows(ratios)

    fig, ax = plt.subplots(figsize=(7, 4.5))
    seen = []
    for r in rows:
        key = (r["method"], r["keyframe_latents"])
        if key not in seen:
            seen.append(key)
    for method, latents in seen:
        ks = [int(r["k_extra"]) for r in rows if (r["method"], r["keyframe_latents"]) == (method, latents)]
        ys = [float(r["rmse_mean"]) for r in rows if (r["method"], r["keyframe_latents"]) == (method, latents)]
        name = method + (f" ({latents} keyframe latents)" if latents else "")
        ax.plot(ks, ys, "o-" if latents != "sample" else "s--", label=name)
    ax.set_xlabel("K_x (extra keyframes besides first and last)")
    ax.set_ylabel("RMSE ×100 (non-keyframes)")
    ax.set_xticks(range(4))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "rmse_vs_kx.png"), dpi=100)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
