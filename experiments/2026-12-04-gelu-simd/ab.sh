#!/usr/bin/env bash
# Before/after of the host GELU's loops under runtime SIMD dispatch (pulp; AVX-512 here) with the vectorisable
# exp of its derivative, alternating two release builds, three rounds, on the otherwise idle 2-core CPU:
#   (1) `eval run` of the shipped small RF (12 validation clips, K_x 0–3, 16-point grid), end to end;
#   (2) `bench train` of the small RF (one micro-batch of 16 clips, P 128, fresh weights), median step of 25.
# BEFORE / AFTER: release builds of the commit before the change and with it. Writes times.csv and summary.csv.
set -euo pipefail
before=${1:?usage: ab.sh BEFORE_BIN AFTER_BIN DATA}; after=${2:?}; data=${3:?}
here=$(cd "$(dirname "$0")" && pwd); root=$(cd "$here/../.." && pwd)
cd "$root"; out=$(mktemp -d)
echo "what,binary,round,seconds" > "$here/times.csv"
for round in 1 2 3; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        start=$(date +%s.%N)
        "$bin" eval run --protocol table1 --data "$data" --clips 12 --n-grid 16 --methods keyframe_rf \
            --rf weights/small/rf --export 0 --no-progress --out "$out/eval-$v-$round" > /dev/null 2>&1
        echo "eval_shipped_rf,$v,$round,$(echo "$(date +%s.%N) - $start" | bc)" >> "$here/times.csv"
        step=$("$bin" bench train --config configs/rf/small.toml --backends flex --tokens 128 --steps 25 2>&1 |
            awk '$1 == "flex" {print $3}')
        echo "rf_train_step_fresh,$v,$round,$step" >> "$here/times.csv"
    done
done
# The metrics must not move: the two builds' table 1 CSVs of round 1, side by side.
cp "$out/eval-before-1/summary.csv" "$here/metrics-before.csv"
cp "$out/eval-after-1/summary.csv" "$here/metrics-after.csv"
python3 - "$here/times.csv" "$here/summary.csv" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
with open(sys.argv[2], "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["what", "before_median_s", "after_median_s", "speedup"])
    for what in dict.fromkeys(r["what"] for r in rows):
        med = {v: statistics.median(float(r["seconds"]) for r in rows if r["what"] == what and r["binary"] == v)
               for v in ("before", "after")}
        w.writerow([what, f"{med['before']:.4f}", f"{med['after']:.4f}", f"{med['before'] / med['after']:.3f}"])
PY
rm -rf "$out"
cat "$here/summary.csv"
