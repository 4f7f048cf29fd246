#!/usr/bin/env bash
# Where on the mesh the frame-wise VAE loses its accuracy: table 5 with per-vertex errors (`eval run --per-vertex`)
# for the shipped VAE (weights/small/vae, procedural clips only) and a VAE trained on procedural + rigged + real
# clips (VAE), on the held-out store whole, 100 procedural validation clips and 200 validation windows of the store
# VAE was trained on; then the same VAE's weights told more latent tokens at inference (P 128 → 256, 512: the FPS
# tokens are points of the mesh, the weights do not depend on their number), held out. analyse.py summarises.
#
#   bash experiments/2026-12-08-vae-error-maps/run.sh HELDOUT PROCEDURAL TRAIN VAE SCRATCH
#
# HELDOUT: scripts/heldout_corpus.sh's store; PROCEDURAL: `data synth --clips 2000 --seed 666 --max-vertices 1024
# --p 128`; TRAIN: VAE's training store; SCRATCH: a folder for the token-count copies of VAE. ANY4D_BIN: the binary
# (default target/release/any4d). The per-vertex files (tens of MB) stay out of git; their summaries are committed.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
usage="usage: run.sh HELDOUT PROCEDURAL TRAIN VAE SCRATCH"
heldout=${1:?$usage}
procedural=${2:?$usage}
train=${3:?$usage}
vae=${4:?$usage}
scratch=${5:?$usage}
bin=${ANY4D_BIN:-$root/target/release/any4d}
cd "$root"
t5() { # OUT ARGS...
  local out=${here#"$root"/}/table5/$1
  shift
  [[ -f $out/vertices.parquet ]] && return
  "$bin" eval run --protocol table5 --per-vertex --posterior mean --no-progress --out "$out" "$@"
}
t5 heldout --data "$heldout" --split all --clips 63 --vae weights/small/vae --vae-b "$vae"
t5 procedural-val --data "$procedural" --clips 100 --vae weights/small/vae --vae-b "$vae"
t5 train-val --data "$train" --clips 200 --vae weights/small/vae --vae-b "$vae"
for p in 256 512; do
  copy=$scratch/vae-p$p
  if [[ ! -d $copy ]]; then
    mkdir -p "$scratch"
    cp -r "$vae" "$copy"
    sed -i "s/^tokens = 128$/tokens = $p/" "$copy/config.toml"
    grep -q "^tokens = $p$" "$copy/config.toml"
  fi
done
t5 heldout-tokens --data "$heldout" --split all --clips 63 --vae "$scratch/vae-p256" --vae-b "$scratch/vae-p512"
python3 "$here/analyse.py"
