#!/usr/bin/env bash
# The SuperTuxKart control: the corpus-arms' best VAE recipe (procedural + rigged clips + the real corpus, augmented;
# configs/vae/small.toml's 2,000 steps) on today's real corpus without SuperTuxKart, from scratch, scored by table 5
# (posterior mean) against the shipped VAE on the held-out real store (whole), 100 windows of the real corpus's
# validation split (the stk-vae experiment's windows), 100 procedural and 100 rigged validation clips; summarise.py
# pairs it with the corpus-arms' vae-srra and the stk-vae experiment's vae-srras where the windows are the same.
#
#   bash experiments/2026-12-07-stk-control/run.sh SCRATCH REAL   # ANY4D_BIN=... if not target/release/any4d
#
# REAL: a folder holding `staged/` (scripts/real_corpus.sh's staging) and `store/` (its store, whose validation
# split is the real-val set); the held-out store is built into SCRATCH by scripts/heldout_corpus.sh. The training
# store leaves SuperTuxKart out (experiments/2026-12-07-stk-vae: it made the VAE worse at this budget).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH REAL}
real=${2:?usage: run.sh SCRATCH REAL}
bin=${ANY4D_BIN:-$root/target/release/any4d}
mkdir -p "$tmp"
cd "$root"
[[ -d $tmp/heldout/store ]] || ANY4D=$bin bash scripts/heldout_corpus.sh "$tmp/heldout"
[[ -d $tmp/p2k128 ]] || "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/p2k128"
[[ -d $tmp/rig ]] || "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/rig"
if [[ ! -d $tmp/sr ]]; then
  "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
  "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
fi
if [[ ! -d $tmp/srr ]]; then
  mkdir -p "$tmp/staged"
  for d in "$real"/staged/*; do
    [[ $(basename "$d") == supertuxkart-data ]] || ln -sfn "$d" "$tmp/staged/"
  done
  cp -r "$tmp/sr" "$tmp/srr"
  "$bin" data import "$tmp/staged" --out "$tmp/srr" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srr_import.log" || [[ $? -eq 2 ]]
fi
"$bin" data inspect "$tmp/srr" >"$here/store.txt"
aug=(--set vae.augment.yaw_degrees=180 --set vae.augment.mirror=0.5 --set 'vae.augment.scale=[0.7,1.3]'
  --set vae.augment.reverse=0.5 --set 'vae.augment.speed=[0.5,1.0]')
arm() { # NAME [--set ...]
  local name=$1
  [[ -d $tmp/runs/$name-1 ]] || "$bin" train vae --config configs/vae/small.toml --data "$tmp/srr" \
    --runs-dir "$tmp/runs" --run "$name" "${aug[@]}" "${@:2}"
  mkdir -p "$here/runs/$name"
  cp "$tmp/runs/$name-1"/{config.toml,log.txt,metrics.csv,valid.csv,latent_stats.json} "$here/runs/$name/"
  t5() {
    [[ -f $here/table5/$name/$2/clips.parquet ]] && return
    "$bin" eval run --protocol table5 --data "$1" --vae weights/small/vae --vae-b "$tmp/runs/$name-1" \
      --posterior mean --out "${here#"$root"/}/table5/$name/$2" "${@:3}"
  }
  t5 "$tmp/heldout/store" heldout --split all --clips 63
  t5 "$real/store" real-val --clips 100
  t5 "$tmp/p2k128" procedural-val --clips 100
  t5 "$tmp/rig" rigged-val --clips 100
}
arm vae-srra-nostk
python3 "$here/summarise.py"
