#!/usr/bin/env bash
# Before/after of the host GELU (docs/method.md §11) with trained weights, where the GELU's inputs are spread
# over the range in which a scalar erf is slow: (1) evaluation with the shipped small RF (12 validation clips,
# 16-point grid, keyframe RF only), timed end to end; (2) the small RF's real training loop (two CPU workers)
# resumed from step 4,000 of runs/rf-v1500-s4500-1 for 330 s per binary, twice, alternating; its metrics.csv
# rows give steps/s. BEFORE / AFTER: release builds of the commit before the change and with it.
set -euo pipefail
before=${1:?usage: ab-trained.sh BEFORE_BIN AFTER_BIN DATA RF_RUN}; after=${2:?}; data=${3:?}; rf_run=${4:?}
here=$(cd "$(dirname "$0")" && pwd); root=$(cd "$here/../.." && pwd)
cd "$root"; mkdir -p "$here/logs" "$here/runs"
for round in 1 2 3; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        start=$(date +%s.%N)
        "$bin" eval run --protocol table1 --data "$data" --clips 12 --n-grid 16 --methods keyframe_rf \
            --rf weights/small/rf --export 0 --no-progress --out "$here/logs/eval-$v-$round" > /dev/null 2>&1
        echo "eval,$v,$round,$(echo "$(date +%s.%N) - $start" | bc)" >> "$here/logs/eval-times.csv"
    done
done
for v in before after; do
    [[ -d $here/runs/rf-$v ]] || { cp -r "$rf_run" "$here/runs/rf-$v"; rm -rf "$here/runs/rf-$v/checkpoints/step_4500"; }
done
for round in 1 2; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        timeout -s INT 330 "$bin" train rf --resume "$here/runs/rf-$v" --data "$data" > "$here/logs/train-$v-$round.txt" 2>&1 || true
        echo "$v round $round: last step $(tail -n 1 "$here/runs/rf-$v/metrics.csv" | cut -d, -f1)"
    done
done
