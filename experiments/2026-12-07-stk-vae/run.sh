#!/usr/bin/env bash
# What SuperTuxKart's characters in the real corpus do to the small frame-wise VAE: configs/vae/small.toml with the
# augmentation of ../2026-12-06-corpus-arms (its best recipe, `vae-srra`) on 2,000 procedural + 2,000 rigged clips
# + the real corpus of scripts/real_corpus.sh, which now holds SuperTuxKart's skinned meshes; table 5 against the
# shipped VAE on the held-out store, the real corpus's validation split and procedural validation clips, and the
# held-out windows paired with the corpus-arms VAEs (summarise.py). With RF=1 it goes on to the anchored keyframe RF
# (configs/rf/anchored_small.toml) on that VAE and its held-out and procedural table 1 — not run for the README.
#
#   bash experiments/2026-12-07-stk-vae/run.sh SCRATCH     # ANY4D_BIN=... if not target/release/any4d
#
# Environment: RF (1 to train and score the anchored RF), RF_STEPS (default 3,000, a third of the preset's 9,000),
# ANCHOR_SCALE (default 0.5, the preset's; the run logs the RMS of Z − A it should be near), PYTHON (with numpy and
# pyarrow). SCRATCH (outside the repository) receives the stores and run folders; tables land in this folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
steps=${RF_STEPS:-3000}
py=${PYTHON:-python3}
scale=${ANCHOR_SCALE:-0.5}
mkdir -p "$tmp"
cd "$root"
[[ -d $tmp/heldout/store ]] || ANY4D=$bin bash scripts/heldout_corpus.sh "$tmp/heldout"
[[ -d $tmp/rc/store ]] || P=128 ANY4D=$bin bash scripts/real_corpus.sh "$tmp/rc"
[[ -d $tmp/p2k128 ]] || "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/p2k128"
if [[ ! -d $tmp/srrs ]]; then
  "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/srrs.tmp"
  "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/srrs.tmp"
  "$bin" data import "$tmp/rc/staged" --out "$tmp/srrs.tmp" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srrs_import.log" || [[ $? -eq 2 ]]
  mv "$tmp/srrs.tmp" "$tmp/srrs"
fi
e=${here#"$root"/}
vae=$tmp/runs/vae-srras-1
[[ -d $vae ]] || "$bin" train vae --config configs/vae/small.toml --data "$tmp/srrs" --runs-dir "$tmp/runs" \
  --run vae-srras --set vae.augment.yaw_degrees=180 --set vae.augment.mirror=0.5 --set 'vae.augment.scale=[0.7,1.3]' \
  --set vae.augment.reverse=0.5 --set 'vae.augment.speed=[0.5,1.0]'
mkdir -p "$here/vae"
for f in config.toml log.txt metrics.csv valid.csv loss.png latent_stats.json; do cp "$vae/$f" "$here/vae/"; done
# Table 5 of the shipped VAE (--vae) and this one (--vae-b) on the held-out store whole, 100 windows of the real
# corpus's validation split and 100 procedural validation clips.
t5() {
  [[ -f $here/table5-$1/clips.parquet ]] ||
    "$bin" eval run --protocol table5 --data "$2" --vae weights/small/vae --vae-b "$vae" --posterior mean \
      --out "$e/table5-$1" "${@:3}"
}
t5 heldout "$tmp/heldout/store" --split all --clips 63
t5 real-val "$tmp/rc/store" --clips 100
t5 procedural-val "$tmp/p2k128" --clips 100
"$py" "$here/summarise.py"
[[ ${RF:-0} == 1 ]] || exit 0
run=$tmp/rfruns/rf-anchor-1
[[ -d $run ]] ||
  "$bin" train rf --config configs/rf/anchored_small.toml --vae "$vae" --data "$tmp/srrs" --runs-dir "$tmp/rfruns" \
    --run rf-anchor --set "train.duration.steps=$steps" --set "model.anchor.keyframe_lerp.scale=$scale"
mkdir -p "$here/rf"
for f in config.toml log.txt metrics.csv valid.csv samples.csv loss.png; do [[ -f $run/$f ]] && cp "$run/$f" "$here/rf/"; done
V=experiments/2026-12-05-vae2000-family
S=experiments/2026-12-04-rf-scale
[[ -f $here/heldout/clips.parquet ]] ||
  "$bin" eval run --protocol table1 --data "$tmp/heldout/store" --split all --manifest $V/heldout/manifest.json \
    --out "$e/heldout" --rf "$run" --n-grid 16 --export 0 --methods keyframe_rf,lerp_latent,vae_oracle
[[ -f $here/procedural-s42/clips.parquet ]] ||
  "$bin" eval run --protocol table1 --data "$tmp/p2k128" --manifest $S/manifest.json --out "$e/procedural-s42" \
    --rf "$run" --n-grid 16 --export 0 --methods keyframe_rf,lerp_latent,lerp
R=experiments/2026-12-06-real-rf
C=experiments/2026-12-06-real-rf/compare.py
"$py" $C "$here/heldout-vs-shipped.csv" \
  shipped=$V/heldout/clips.parquet:keyframe_rf anchored=$e/heldout/clips.parquet:keyframe_rf \
  real_rf=$R/heldout/clips.parquet:keyframe_rf lerp=$V/heldout/clips.parquet:lerp \
  latent_lerp=$e/heldout/clips.parquet:lerp_latent vae_oracle=$e/heldout/clips.parquet:vae_oracle
"$py" $C "$here/procedural-vs-shipped.csv" \
  shipped=$V/table1-s42/clips.parquet:keyframe_rf anchored=$e/procedural-s42/clips.parquet:keyframe_rf \
  lerp=$e/procedural-s42/clips.parquet:lerp latent_lerp=$e/procedural-s42/clips.parquet:lerp_latent
