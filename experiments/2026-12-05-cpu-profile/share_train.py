#!/usr/bin/env python3
"""Where a running training process spends its samples, with share.py's categories, plus the samples under burn's
optimiser step.

    perf record -F 199 --call-graph dwarf,16384 -p PID -- sleep 40
    perf script -F time,ip,sym > stacks.txt
    python3 share_train.py stacks.txt > share-small-rf-train.csv
"""
import csv
import sys

from share import CATEGORIES, categorise, records

recs = [s for _, s in records(sys.argv[1])]
counts = categorise(recs)
optim = sum(1 for s in recs if any("burn_optim" in f for f in s))
out = csv.writer(sys.stdout)
out.writerow(["category", "samples", "share"])
out.writerow(["all samples", len(recs), "1.0000"])
for c, _ in CATEGORIES:
    out.writerow([c, counts[c], f"{counts[c] / len(recs):.4f}"])
out.writerow(["(also) burn's optimiser step (AdamW), any leaf", optim, f"{optim / len(recs):.4f}"])
