#!/usr/bin/env bash
# Does scaling motion about frame 0 (vae.augment.motion, docs/method.md §2.9) teach the small frame-wise VAE the large
# displacements it fails on held out (../2026-12-08-vae-error-maps)? The separating arm of ../2026-12-07-vae-repro
# (vae-srra's recipe and augmentation, 2,000 steps, on its store: a5fd204 procedural and rigged clips + the real
# corpus without SuperTuxKart) trained again with one change, motion scaled by a factor drawn in [1, 1.5]; scored by
# table 5 (posterior mean) on the held-out store whole and 100 procedural validation clips, paired with that arm.
#
#   bash experiments/2026-12-08-motion-aug/run.sh STORE PROCEDURAL HELDOUT RUNS
#
# STORE: the arm's store (vae-repro's arm.sh makes it as SCRATCH/srr-rig5); PROCEDURAL: `data synth --clips 2000
# --seed 666 --max-vertices 1024 --p 128`; HELDOUT: scripts/heldout_corpus.sh's store; RUNS: where the run folder
# goes. ANY4D_BIN: the binary (default target/release/any4d).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
usage="usage: run.sh STORE PROCEDURAL HELDOUT RUNS"
store=${1:?$usage}
procedural=${2:?$usage}
heldout=${3:?$usage}
runs=${4:?$usage}
bin=${ANY4D_BIN:-$root/target/release/any4d}
name=vae-motion15
cd "$root"
aug=(--set vae.augment.yaw_degrees=180 --set vae.augment.mirror=0.5 --set 'vae.augment.scale=[0.7,1.3]'
  --set vae.augment.reverse=0.5 --set 'vae.augment.speed=[0.5,1.0]' --set 'vae.augment.motion=[1.0,1.5]')
# Latent statistics from 2,048 windows and validation on 256 (neither enters training or table 5).
[[ -f $runs/$name-1/latent_stats.json ]] || "$bin" train vae --config configs/vae/small.toml --data "$store" \
  --runs-dir "$runs" --run "$name" "${aug[@]}" --set vae.stats_windows=2048 --set vae.valid_windows=256
mkdir -p "$here/runs/$name"
cp "$runs/$name-1"/{config.toml,metrics.csv,valid.csv,latent_stats.json} "$here/runs/$name/"
sed "s#$runs/##g" "$runs/$name-1/log.txt" >"$here/runs/$name/log.txt"
t5() {
  local out=${here#"$root"/}/table5/$2
  [[ -f $out/clips.parquet ]] && return
  "$bin" eval run --protocol table5 --data "$1" --vae weights/small/vae --vae-b "$runs/$name-1" --posterior mean \
    --no-progress --out "$out" "${@:3}"
}
t5 "$heldout" heldout --split all --clips 63
t5 "$procedural" procedural-val --clips 100
python3 "$here/summarise.py"
