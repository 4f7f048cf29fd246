#!/usr/bin/env python3
"""runs.csv (from run.sh) → summary.csv: per preset the median over repetitions of each binary's per-run median
steps/s, their ratio (new ÷ old), and the ratio within each repetition (old and new ran back to back)."""
import csv
import statistics
import sys
from collections import defaultdict

src = sys.argv[1] if len(sys.argv) > 1 else "runs.csv"
out = sys.argv[2] if len(sys.argv) > 2 else "summary.csv"
runs = list(csv.DictReader(open(src)))
cells = defaultdict(dict)
for r in runs:
    cells[r["preset"]][(r["binary"], r["rep"])] = float(r["median_steps_per_s"])
rows = []
for preset, values in cells.items():
    reps = sorted({rep for _, rep in values})
    old = [values[("old", rep)] for rep in reps]
    new = [values[("new", rep)] for rep in reps]
    paired = [n / o for o, n in zip(old, new)]
    rows.append([preset, len(reps), f"{statistics.median(old):.3f}", f"{statistics.median(new):.3f}",
                 f"{statistics.median(new) / statistics.median(old):.2f}", f"{min(paired):.2f}", f"{max(paired):.2f}"])
with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["preset", "reps", "old_median_steps_per_s", "new_median_steps_per_s", "new_over_old",
                "per_rep_ratio_min", "per_rep_ratio_max"])
    w.writerows(rows)
for row in rows:
    print(",".join(map(str, row)))
