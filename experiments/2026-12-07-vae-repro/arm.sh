#!/usr/bin/env bash
# The separating run: vae-srra's recipe (configs/vae/small.toml's 2,000 steps, vae-srra's augmentation) on the
# stk-control's store (today's real corpus without SuperTuxKart) with one change: the rigged clips made by the
# a5fd204 generator that vae-srra was trained on (vigorous run and jump) instead of today's. Scored by table 5
# (posterior mean) on the held-out store whole and 100 procedural validation clips, against the shipped VAE.
#
#   bash experiments/2026-12-07-vae-repro/arm.sh SCRATCH REAL HELDOUT
#
# SCRATCH must hold gen-a5fd204/sr (run.sh with ANY4D_SYNTH_BIN = a build of a5fd204); REAL holds `staged/`;
# HELDOUT is scripts/heldout_corpus.sh's output folder (its store/). ANY4D_BIN as in run.sh.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
usage="usage: arm.sh SCRATCH REAL HELDOUT"
tmp=${1:?$usage}
real=${2:?$usage}
heldout=${3:?$usage}
bin=${ANY4D_BIN:-$root/target/release/any4d}
name=vae-srra-nostk-rig5
cd "$root"
[[ -d $heldout/store ]] || ANY4D=$bin bash scripts/heldout_corpus.sh "$heldout"
[[ -d $tmp/p2k128 ]] || "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/p2k128"
store=$tmp/srr-rig5
if [[ ! -d $store ]]; then
  mkdir -p "$tmp/staged-nostk"
  for d in "$real"/staged/*; do
    [[ $(basename "$d") == supertuxkart-data ]] || ln -sfn "$d" "$tmp/staged-nostk/"
  done
  cp -r "$tmp/gen-a5fd204/sr" "$store"
  "$bin" data import "$tmp/staged-nostk" --out "$store" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srr-rig5_import.log" || [[ $? -eq 2 ]]
fi
mkdir -p "$here/stores/arm"
"$bin" data inspect "$store" | sed -E "s#$tmp/##g; s#/[^ ]*/(staged[^/]*/)#\1#g" >"$here/stores/arm/$name.txt"
aug=(--set vae.augment.yaw_degrees=180 --set vae.augment.mirror=0.5 --set 'vae.augment.scale=[0.7,1.3]'
  --set vae.augment.reverse=0.5 --set 'vae.augment.speed=[0.5,1.0]')
# Latent statistics from 2,048 windows (they do not enter table 5's reconstructions).
[[ -f $tmp/runs/$name-1/latent_stats.json ]] || "$bin" train vae --config configs/vae/small.toml --data "$store" \
  --runs-dir "$tmp/runs" --run "$name" "${aug[@]}" --set vae.stats_windows=2048
mkdir -p "$here/runs/arm/$name"
cp "$tmp/runs/$name-1"/{config.toml,metrics.csv,valid.csv,latent_stats.json} "$here/runs/arm/$name/"
sed "s#$tmp/##g" "$tmp/runs/$name-1/log.txt" >"$here/runs/arm/$name/log.txt"
t5() {
  [[ -f $here/table5/$name/$2/clips.parquet ]] && return
  "$bin" eval run --protocol table5 --data "$1" --vae weights/small/vae --vae-b "$tmp/runs/$name-1" \
    --posterior mean --out "${here#"$root"/}/table5/$name/$2" "${@:3}"
}
t5 "$heldout/store" heldout --split all --clips 63
t5 "$tmp/p2k128" procedural-val --clips 100
python3 "$here/summarise.py"
