#!/usr/bin/env python3
"""ab.csv from logs/ab-{old,new}-t{1,2}-r*.txt: per network and thread count, each binary's median time, PyTorch's
median time in its runs, ours/PyTorch (median of the rounds' ratios) and the speed-up old/new (median of the
rounds' ratios of ours' times; each round runs old then new back to back)."""
import csv
import glob
import os
import re
import statistics

import summarise

here = os.path.dirname(os.path.abspath(__file__))
NETS = [log_name for log_name, _ in summarise.NETS]
cells = {}  # (which, threads, round, net) -> (ours, torch, ratio)
for path in glob.glob(f"{here}/logs/ab-*-t*-r*.txt"):
    which, threads, rnd = re.search(r"ab-(old|new)-t(\d)-r(\d)\.txt", path).groups()
    for net, row in summarise.bench_rows(path).items():
        cells[(which, int(threads), int(rnd), net)] = row
rounds = sorted({k[2] for k in cells})
with open(f"{here}/ab.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["network", "threads", "rounds", "old_ms", "new_ms", "speedup_median", "speedup_min", "speedup_max",
                "old_over_pytorch", "new_over_pytorch", "pytorch_ms_in_old_runs", "pytorch_ms_in_new_runs"])
    for threads in (1, 2):
        for net in NETS:
            old = [cells[("old", threads, r, net)] for r in rounds]
            new = [cells[("new", threads, r, net)] for r in rounds]
            sp = [o[0] / n[0] for o, n in zip(old, new)]
            w.writerow([net, threads, len(rounds), f"{statistics.median(o[0] for o in old):.1f}",
                        f"{statistics.median(n[0] for n in new):.1f}", f"{statistics.median(sp):.2f}",
                        f"{min(sp):.2f}", f"{max(sp):.2f}", f"{statistics.median(o[2] for o in old):.2f}",
                        f"{statistics.median(n[2] for n in new):.2f}", f"{statistics.median(o[1] for o in old):.1f}",
                        f"{statistics.median(n[1] for n in new):.1f}"])
print(open(f"{here}/ab.csv").read())
