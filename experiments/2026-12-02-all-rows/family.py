#!/usr/bin/env python3
"""RMSE per motion family of the procedural clips, every method of one `eval run` (table1 or table5) against lerp.

Usage: python3 family.py CLIPS_PARQUET OUT_CSV
The motion family is the third field of a synthetic clip id (`synth-<shape>-<motion>-...`). Writes one row per
(method, motion, K_x): clips × seeds, mean RMSE ×100 and the ratio to lerp's mean on the same clips (empty without
a lerp row, as in table5); prints the ratios (or, without lerp, the RMSE ×100) as a table, one column per K_x.
Needs pyarrow.
"""
import csv
import sys
from collections import defaultdict

import pyarrow.parquet as pq


def main(clips, out):
    rmse = defaultdict(list)
    for r in pq.read_table(clips).to_pylist():
        motion = r["clip_id"].split("-")[2]
        rmse[(r["method"], motion, r["k_extra"])].append(r["rmse"])
    methods = sorted({m for m, _, _ in rmse}, key=lambda m: (m != "lerp", m))
    motions = sorted({mo for _, mo, _ in rmse})
    ks = sorted({k for _, _, k in rmse})
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "motion", "k_extra", "clips_x_seeds", "rmse_x100", "ratio_to_lerp"])
        for m in methods:
            for mo in motions:
                for k in ks:
                    v, l = rmse.get((m, mo, k)), rmse.get(("lerp", mo, k))
                    if v:
                        ratio = f"{mean(v) / mean(l):.3f}" if l else ""
                        w.writerow([m, mo, k, len(v), f"{100 * mean(v):.3f}", ratio])
    print(f"{'method':16s} {'motion':8s} n  " + "  ".join(f"K_x {k}" for k in ks))
    for m in methods:
        for mo in motions:
            # Ratios to lerp; RMSE ×100 when the run has no lerp row (table5).
            base = {k: mean(rmse[("lerp", mo, k)]) if ("lerp", mo, k) in rmse else 0.01 for k in ks}
            ratios = [mean(rmse[(m, mo, k)]) / base[k] for k in ks if (m, mo, k) in rmse]
            n = len(rmse.get((m, mo, ks[0]), []))
            print(f"{m:16s} {mo:8s} {n:3d} " + "  ".join(f"{x:5.2f}" for x in ratios))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
