#!/usr/bin/env bash
# Build the whole training corpus into OUT/store from nothing: procedural shape clips, rigged procedural characters
# (`data synth --family rigged`) and the real corpus of scripts/real_corpus.sh (downloaded, staged and imported
# into the same store, short looping takes played round). Prints the store summary and the wall time.
#
#   scripts/training_corpus.sh OUT        (ANY4D=path/to/any4d to use a built binary; default: a release build)
#
# Sizes (environment): SHAPES=32000 and RIGGED=25000 procedural clips (seed SEED=666; a store of fewer clips of
# the same seed holds the first of these, in the same splits), 16-frame windows every 8 frames of the real takes,
# P=128 FPS tokens (the small presets'; 512 for the paper's), procedural meshes of at most SYNTH_MAX_VERTICES=1024
# vertices and real meshes of 128–4,096. With the defaults: 63,456 windows, 50,956 of them in the train split,
# 25,434 of those articulated (rigged or real). Splits are drawn per object, so every procedural validation clip
# of a smaller store of the same seed is a validation clip here too.
set -euo pipefail
OUT=${1:?usage: scripts/training_corpus.sh OUT}
SHAPES=${SHAPES:-32000}
RIGGED=${RIGGED:-25000}
SEED=${SEED:-666}
P=${P:-128}
SYNTH_MAX_VERTICES=${SYNTH_MAX_VERTICES:-1024}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [[ -n "${ANY4D:-}" ]]; then
  any4d() { "$ANY4D" "$@"; }
else
  cargo build --quiet --release --locked --manifest-path "$ROOT/Cargo.toml"
  ANY4D=$ROOT/target/release/any4d
  any4d() { "$ANY4D" "$@"; }
fi
export ANY4D
start=$(date +%s)
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
# The real packages: downloaded, unpacked and staged by real_corpus.sh (its own store, at this P, is kept too).
P=$P bash "$ROOT/scripts/real_corpus.sh" "$OUT/real" | tail -n 1
rm -rf "$OUT/store"
any4d data synth --clips "$SHAPES" --seed "$SEED" --max-vertices "$SYNTH_MAX_VERTICES" --p "$P" --out "$OUT/store" |
  tail -n 1
any4d data synth --family rigged --clips "$RIGGED" --seed "$SEED" --max-vertices "$SYNTH_MAX_VERTICES" --p "$P" \
  --out "$OUT/store" | tail -n 1
echo "procedural clips written in $(($(date +%s) - start)) s"
any4d data import "$OUT/real/staged" --out "$OUT/store" --frames 16 --stride 8 --p "$P" --min-vertices 128 \
  --max-vertices 4096 --loop-short >"$OUT/import.log" || rc=$?
# Exit code 2 means some takes were rejected (listed in import.log); the store is written.
if [[ ${rc:-0} -ne 0 && ${rc:-0} -ne 2 ]]; then cat "$OUT/import.log"; exit "$rc"; fi
any4d data inspect "$OUT/store" | grep -v "^  rejected" | head -n 30
echo "training corpus: $OUT/store, wall time $(($(date +%s) - start)) s"
