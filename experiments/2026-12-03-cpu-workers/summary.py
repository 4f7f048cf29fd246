#!/usr/bin/env python3
"""runs.csv (from run.sh) → summary.csv: per preset and configuration the median over repetitions of the per-run
median steps/s, and its ratio to the commit before the change on one device (same preset)."""
import csv
import statistics
import sys
from collections import defaultdict

src = sys.argv[1] if len(sys.argv) > 1 else "runs.csv"
out = sys.argv[2] if len(sys.argv) > 2 else "summary.csv"
cells = defaultdict(list)
for r in csv.DictReader(open(src)):
    cells[(r["preset"], r["binary"], r["devices"], r["micro_batch"])].append(float(r["median_steps_per_s"]))
rows = []
for (preset, binary, devices, micro), values in cells.items():
    base = [v for (p, b, d, _), v in cells.items() if p == preset and b == "old" and d == "flex"]
    med = statistics.median(values)
    ref = statistics.median(base[0]) if base else float("nan")
    rows.append([preset, binary, devices, micro, len(values), f"{min(values):.3f}", f"{med:.3f}", f"{max(values):.3f}",
                 f"{med / ref:.2f}"])
with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["preset", "binary", "devices", "micro_batch", "runs", "min_steps_per_s", "median_steps_per_s",
                "max_steps_per_s", "vs_before"])
    w.writerows(rows)
for row in rows:
    print(",".join(map(str, row)))

try:  # a bar chart of the medians beside the CSV (matplotlib optional)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = list(dict.fromkeys(r[0] for r in rows))
    configs = list(dict.fromkeys((r[1], r[2]) for r in rows))
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / len(configs)
    for i, (binary, devices) in enumerate(configs):
        ratios = [next((float(r[8]) for r in rows if r[0] == p and (r[1], r[2]) == (binary, devices)), 0.0)
                  for p in presets]
        ax.bar([x + i * width for x in range(len(presets))], ratios, width,
               label=f"{'before' if binary == 'old' else 'after'}, {devices.replace('+', ' + ')}")
    ax.axhline(2.0, color="grey", lw=0.8, ls="--")
    ax.set_xticks([x + width * (len(configs) - 1) / 2 for x in range(len(presets))], presets)
    ax.set_ylabel("steps/s ÷ before (one device)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out.rsplit("/", 1)[0] + "/speedup.png" if "/" in out else "speedup.png", dpi=120)
except ImportError:
    pass
