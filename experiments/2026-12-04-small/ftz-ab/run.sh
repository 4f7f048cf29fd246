#!/usr/bin/env bash
# The A/B of docs/method.md §10: the small VAE run of experiments/2026-12-03-vae-1500 (runs/vae-1500-1) resumed from
# its step-1,250 checkpoint for 75 s, twice per binary, alternating, on the otherwise idle 2-core CPU: BEFORE is a
# release build of 13e4558 (subnormal floats kept), AFTER one of 06257c1 (train.flush_denormals, default true).
# Each binary continues its own copy of the run, so the second round starts where its first stopped.
set -euo pipefail
before=${1:?usage: run.sh BEFORE_BIN AFTER_BIN DATA}; after=${2:?}; data=${3:?}
mkdir -p runs
for v in off on; do
    [[ -d runs/vae-$v ]] || { cp -r ../../../runs/vae-1500-1 runs/vae-$v; rm -rf runs/vae-$v/checkpoints/step_1500; }
done
for round in 1 2; do
    for v in off on; do
        bin=$before; [[ $v == on ]] && bin=$after
        timeout -s INT 75 "$bin" train vae --resume runs/vae-$v --data "$data" > /dev/null 2>&1 || true
        echo "$v round $round: last step $(tail -n 1 runs/vae-$v/metrics.csv | cut -d, -f1)"
    done
done
# metrics-off.csv / metrics-on.csv hold the rows each resumed run appended (after the original 1,500).
