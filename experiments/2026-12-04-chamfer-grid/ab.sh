#!/usr/bin/env bash
# Before/after of Chamfer's paired nearest-neighbour search in a cell grid (eval/src/nearest.rs), alternating two
# release builds, three rounds, on the otherwise idle 2-core CPU: `any4d bench metrics` (E1)–(E7) on 8 synthetic
# clips × 16 frames × 4096 vertices, ours on 1 and 2 threads and the numpy + scipy reference on one core, each the
# median of 5 runs, in one process per build and round.
# BEFORE / AFTER: release builds of the commit before the change and with it. Writes runs/*.txt, rates.csv and
# summary.csv.
set -euo pipefail
before=${1:?usage: ab.sh BEFORE_BIN AFTER_BIN}; after=${2:?}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$here/runs"
echo "binary,round,ours_1_thread_clips_s,ours_2_threads_clips_s,reference_clips_s,speedup_1_thread,speedup_2_threads" \
    > "$here/rates.csv"
for round in 1 2 3; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        "$bin" bench metrics --clips 8 --repeat 5 > "$here/runs/$v-$round.txt" 2>&1
        python3 - "$here/runs/$v-$round.txt" "$v" "$round" >> "$here/rates.csv" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
rate = lambda label: re.search(label + r"\s+([0-9.]+) clips/s", text).group(1)
speed = re.search(r"speed-up over the reference: ([0-9.]+)× \(1 thread\), ([0-9.]+)×", text)
print(",".join([sys.argv[2], sys.argv[3], rate(r"ours, 1 thread"), rate(r"ours,\s+2 threads"),
                rate(r"numpy\+scipy, 1 core"), speed.group(1), speed.group(2)]))
PY
    done
done
python3 - "$here/rates.csv" "$here/summary.csv" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
cols = [c for c in rows[0] if c not in ("binary", "round")]
with open(sys.argv[2], "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["binary"] + [f"{c}_median" for c in cols] + [f"{c}_min" for c in cols] + [f"{c}_max" for c in cols])
    for v in ("before", "after"):
        vals = {c: [float(r[c]) for r in rows if r["binary"] == v] for c in cols}
        w.writerow([v] + [f"{statistics.median(vals[c]):.2f}" for c in cols] + [f"{min(vals[c]):.2f}" for c in cols]
                   + [f"{max(vals[c]):.2f}" for c in cols])
PY
cat "$here/summary.csv"
