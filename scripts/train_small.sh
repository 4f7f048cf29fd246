#!/usr/bin/env bash
# Trains the small family from scratch, one model after the other, and times each step: the procedural store, the
# frame-wise VAE (configs/vae/small.toml), ours (configs/rf/small.toml) on that VAE and the replacement Baseline
# (configs/rf/baseline_small.toml) on the same VAE. It is the recipe of weights/small in one command (those runs were
# made by the same presets one at a time, so this trains a replicate of them; it is not claimed to repeat them bit
# for bit):
#
#   scripts/train_small.sh OUT               # ANY4D_BIN=path/to/any4d if not target/release/any4d
#
# OUT/store is the store (2,000 clips, seed 666), OUT/runs/{vae,rf,baseline}-1 the three run folders, OUT/times.csv
# the wall time of each step in seconds, and OUT/*.log each step's output. Pack the runs for sampling with
# `any4d model pack` (weights/small/PROVENANCE.md).
set -euo pipefail

out=${1:?usage: scripts/train_small.sh OUT}
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${ANY4D_BIN:-$root/target/release/any4d}
[[ "$bin" == /* ]] || bin=$PWD/$bin
if [[ ! -x "$bin" ]]; then
    echo "error: $bin is not an executable (cargo build --release -p any4d, or set ANY4D_BIN)" >&2
    exit 2
fi
if [[ -e "$out/times.csv" ]]; then
    echo "error: $out/times.csv exists: give a fresh OUT folder" >&2
    exit 2
fi
mkdir -p "$out/runs"
out=$(cd "$out" && pwd)   # the steps run from the repository root
echo "step,seconds,command" > "$out/times.csv"

# step NAME COMMAND...: runs the command, appends its wall time to times.csv, keeps its output in NAME.log.
step() {
    local name=$1
    shift
    local start end
    start=$(date +%s)
    echo "[$(date -u +%H:%M:%S)] $name: $*"
    "$@" > "$out/$name.log" 2>&1 || {
        echo "error: $name failed; its output is $out/$name.log" >&2
        tail -n 5 "$out/$name.log" >&2
        exit 1
    }
    end=$(date +%s)
    echo "$name,$((end - start)),\"$*\"" >> "$out/times.csv"
}

cd "$root"
step data "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$out/store"
step vae "$bin" train vae --config configs/vae/small.toml --data "$out/store" --runs-dir "$out/runs" --run vae
step rf "$bin" train rf --config configs/rf/small.toml --vae "$out/runs/vae-1" --data "$out/store" \
    --runs-dir "$out/runs" --run rf
step baseline "$bin" train rf --config configs/rf/baseline_small.toml --vae "$out/runs/vae-1" --data "$out/store" \
    --runs-dir "$out/runs" --run baseline
awk -F, 'NR > 2 { s += $2 } END { printf "training (vae + rf + baseline): %d s = %d h %d min\n", s, s / 3600, (s % 3600) / 60 }' \
    "$out/times.csv" | tee "$out/total.txt"
