"""Jerk of every row as a ratio of means (Σ jerk / Σ ground-truth jerk over the windows) beside the tables' mean of
per-window ratios, which windows whose ground truth barely moves (jerk ≈ 0) dominate.
Usage: python3 jerk.py table1/clips.parquet table2/clips.parquet > jerk.csv"""
import sys
import numpy as np
import pyarrow.parquet as pq

print("table,method,k_extra,windows,jerk_ratio_mean_of_ratios,jerk_ratio_of_means,seam_jerk_ratio_mean_of_ratios,"
      "seam_jerk_ratio_of_means")
for path in sys.argv[1:]:
    t = pq.read_table(path).to_pydict()
    table = "table2" if "seam_jerk" in t else "table1"
    groups = {}
    for i, m in enumerate(t["method"]):
        groups.setdefault((m, t["k_extra"][i]), []).append(i)
    for (m, k), idx in groups.items():
        col = lambda c: np.array([t[c][i] for i in idx], dtype=float)
        row = [table, m, "" if k is None else k, len(idx), col("jerk_ratio").mean(), col("jerk").sum() / col("jerk_gt").sum()]
        if table == "table2":
            row += [col("seam_jerk_ratio").mean(), col("seam_jerk").sum() / col("seam_jerk_gt").sum()]
        else:
            row += ["", ""]
        print(",".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row))
