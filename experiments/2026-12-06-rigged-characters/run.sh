#!/usr/bin/env bash
# What rigged procedural characters buy the frame-wise VAE: configs/vae/small.toml trained from scratch for its 2,000
# steps on the shipped procedural store plus 2,000 rigged characters, against the shipped VAE (the same preset on
# the procedural store alone), both scored by table 5 (posterior mean) on the held-out real store, the real
# corpus's validation split, procedural validation clips and rigged validation clips; and the generator's speed.
#
#   bash experiments/2026-12-06-rigged-characters/run.sh SCRATCH     # ANY4D_BIN=... if not target/release/any4d
#
# SCRATCH (outside the repository) receives the stores and the run folder; the tables land in this folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
mkdir -p "$tmp"
cd "$root"
# Stores: the held-out real store, the real training corpus (for its validation split), the shipped procedural
# store, the rigged store of the same seed, and both together (what the new VAE trains on).
[[ -d $tmp/heldout/store ]] || ANY4D=$bin bash scripts/heldout_corpus.sh "$tmp/heldout"
[[ -d $tmp/rc/store ]] || ANY4D=$bin bash scripts/real_corpus.sh "$tmp/rc"
[[ -d $tmp/p2k128 ]] || "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/p2k128"
[[ -d $tmp/rig ]] || "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/rig"
if [[ ! -d $tmp/sr ]]; then
  "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
  "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
fi
[[ -d $tmp/runs/vae-sr-1 ]] || "$bin" train vae --config configs/vae/small.toml --data "$tmp/sr" --runs-dir "$tmp/runs" --run vae-sr
# Table 5 of both VAEs on the same windows (--vae = shipped, --vae-b = shapes + rigged).
t5() {
  "$bin" eval run --protocol table5 --data "$1" --vae weights/small/vae --vae-b "$tmp/runs/vae-sr-1" \
    --posterior mean --out "$here/table5/$2" "${@:3}"
}
t5 "$tmp/heldout/store" heldout --split all --clips 63
t5 "$tmp/rc/store" real-val --clips 100
t5 "$tmp/p2k128" procedural-val --clips 100
t5 "$tmp/rig" rigged-val --clips 100
python3 "$here/summarise.py"
"$bin" bench synth --clips 200 --repeat 3 | tee "$here/bench-synth.txt"
