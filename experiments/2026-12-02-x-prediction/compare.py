#!/usr/bin/env python3
"""Merge `eval run --protocol table1` summaries of several RF variants (same manifest) into one table.

Usage: python3 compare.py OUT_DIR LABEL=EVAL_DIR [LABEL=EVAL_DIR ...]
Every EVAL_DIR must hold the same manifest.json. The `keyframe_rf` row of each becomes the row LABEL; `lerp` (and
`replacement_rf`, `keyframe_rf_mean<N>` when present) are kept once, from the first folder that has them.
Writes OUT_DIR/summary.csv (every row), OUT_DIR/ratios.csv (each variant against lerp and against the first
variant) and OUT_DIR/rmse_vs_kx.png.
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
    rows, digests, variants = [], set(), []
    for pair in pairs:
        label, folder = pair.split("=", 1)
        with open(os.path.join(folder, "manifest.json"), "rb") as f:
            digests.add(hashlib.sha256(f.read()).hexdigest())
        variants.append(label)
        with open(os.path.join(folder, "summary.csv")) as f:
            for r in csv.DictReader(f):
                name = label if r["method"] == "keyframe_rf" else r["method"]
                if any((x["row"], x["k_extra"]) == (name, r["k_extra"]) for x in rows):
                    continue
                r.pop("data", None)
                rows.append({"row": name, **r})
    if len(digests) != 1:
        sys.exit("the evaluations used different manifests")
    with open(os.path.join(out, "summary.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)

    def value(row, k, col="rmse_mean"):
        for r in rows:
            if r["row"] == row and r["k_extra"] == str(k):
                return float(r[col]) if r[col] != "" else None  # one seed: no interval
        return None

    def fmt(x, digits):
        return "" if x is None else f"{x:.{digits}f}"

    ks = sorted({int(r["k_extra"]) for r in rows})
    with open(os.path.join(out, "ratios.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["row", "k_extra", "rmse", "rmse_ci95", "over_lerp", f"over_{variants[0]}", "jerk_over_gt", "chamfer"])
        for v in variants:
            for k in ks:
                rmse = value(v, k)
                w.writerow([
                    v,
                    k,
                    f"{rmse:.4f}",
                    fmt(value(v, k, "rmse_ci95"), 4),
                    f"{rmse / value('lerp', k):.4f}",
                    f"{rmse / value(variants[0], k):.4f}",
                    f"{value(v, k, 'jerk_ratio_mean'):.2f}",
                    f"{value(v, k, 'chamfer_mean'):.4f}",
                ])
    fig, ax = plt.subplots(figsize=(6, 4))
    for name in variants + [r for r in ("lerp", "replacement_rf") if value(r, 0) is not None]:
        ci = [value(name, k, "rmse_ci95") or 0.0 for k in ks]
        ax.errorbar(ks, [value(name, k) for k in ks], yerr=ci, marker="o", capsize=3, label=name)
    ax.set_xlabel("extra keyframes K_x")
    ax.set_ylabel("RMSE ×100 (non-keyframes)")
    ax.set_xticks(ks)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "rmse_vs_kx.png"), dpi=120)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
