#!/usr/bin/env bash
# Keyframe correction (docs/method.md §5.6, (L2)): does moving a latent method's output by its keyframes' decoding
# residuals close the gap to vertex lerp on real characters? Chosen on data that is not held out — 100 windows of the
# real corpus's validation split (scripts/real_corpus.sh) and the procedural validation clips of the shipped family's
# table 1 — for two keyframe RFs: the shipped one (weights/small, procedural only) and the anchored probe of
# ../2026-12-07-stk-vae (2,000 steps on a VAE trained with real clips). The held-out store is scored once, after.
#
#   bash experiments/2026-12-07-keyframe-correction/run.sh SCRATCH   # ANY4D_BIN=... if not target/release/any4d
#
# SCRATCH holds ../2026-12-07-stk-vae's scratch: heldout/store, rc/store, p2k128, rfruns/rf-anchor-1 (its run.sh
# with RF=1 RF_STEPS=2000 makes them). PYTHON: a Python with numpy and pyarrow. Run from anywhere; tables land here.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
py=${PYTHON:-python3}
cd "$root"
e=${here#"$root"/}
anchored=$tmp/rfruns/rf-anchor-1
shipped=(--rf weights/small/rf --vae weights/small/vae)
t1() { # OUT DATA ARGS...: one table-1 run, skipped when its clips are there
  local out=$1 data=$2
  shift 2
  [[ -f $e/$out/clips.parquet ]] ||
    "$bin" eval run --protocol table1 --data "$data" --out "$e/$out" --n-grid 16 --export 0 --no-progress "$@"
}
# Selection: the real corpus's validation split (100 windows, seed 42) and procedural validation clips.
t1 realval-shipped "$tmp/rc/store" --split val --clips 100 "${shipped[@]}" \
  --methods lerp,lerp_latent,lerp_latent_corrected,keyframe_rf,keyframe_rf_corrected
t1 realval-anchored "$tmp/rc/store" --manifest $e/realval-shipped/manifest.json --rf "$anchored" \
  --methods lerp_latent,lerp_latent_corrected,keyframe_rf,keyframe_rf_corrected
t1 realval-anchored-mean8 "$tmp/rc/store" --manifest $e/realval-shipped/manifest.json --rf "$anchored" \
  --methods keyframe_rf_mean8_corrected
t1 procval-shipped "$tmp/p2k128" --manifest experiments/2026-12-04-rf-scale/manifest.json "${shipped[@]}" \
  --methods lerp,lerp_latent_corrected,keyframe_rf,keyframe_rf_corrected
# Held out, scored once: the windows, keyframes and seeds of the shipped family's held-out table.
V=experiments/2026-12-05-vae2000-family
t1 heldout-shipped "$tmp/heldout/store" --split all --manifest $V/heldout/manifest.json "${shipped[@]}" \
  --methods lerp_latent,lerp_latent_corrected,keyframe_rf_corrected
t1 heldout-anchored "$tmp/heldout/store" --split all --manifest $V/heldout/manifest.json --rf "$anchored" \
  --methods lerp_latent_corrected,keyframe_rf_corrected
t1 heldout-anchored-mean8 "$tmp/heldout/store" --split all --manifest $V/heldout/manifest.json --rf "$anchored" \
  --methods keyframe_rf_mean8_corrected
C=experiments/2026-12-06-real-rf/compare.py
B=$e/motion_bins.py
R=$e/realval
"$py" $C $e/realval.csv lerp=$R-shipped/clips.parquet:lerp \
  shipped=$R-shipped/clips.parquet:keyframe_rf shipped_corrected=$R-shipped/clips.parquet:keyframe_rf_corrected \
  anchored=$R-anchored/clips.parquet:keyframe_rf anchored_corrected=$R-anchored/clips.parquet:keyframe_rf_corrected \
  anchored_mean8_corrected=$R-anchored-mean8/clips.parquet:keyframe_rf_mean8_corrected \
  shipped_latent_lerp=$R-shipped/clips.parquet:lerp_latent \
  shipped_latent_lerp_corrected=$R-shipped/clips.parquet:lerp_latent_corrected \
  anchored_latent_lerp=$R-anchored/clips.parquet:lerp_latent \
  anchored_latent_lerp_corrected=$R-anchored/clips.parquet:lerp_latent_corrected
"$py" $B $e/realval-motion-bins.csv lerp=$R-shipped/clips.parquet:lerp \
  shipped=$R-shipped/clips.parquet:keyframe_rf shipped_corrected=$R-shipped/clips.parquet:keyframe_rf_corrected \
  anchored=$R-anchored/clips.parquet:keyframe_rf anchored_corrected=$R-anchored/clips.parquet:keyframe_rf_corrected \
  anchored_mean8_corrected=$R-anchored-mean8/clips.parquet:keyframe_rf_mean8_corrected
P=$e/procval-shipped/clips.parquet
"$py" $C $e/procval.csv lerp=$P:lerp shipped=$P:keyframe_rf shipped_corrected=$P:keyframe_rf_corrected \
  shipped_latent_lerp_corrected=$P:lerp_latent_corrected
# Held out: the uncorrected rows are the committed ones of the same windows, keyframes and seeds.
S=experiments/2026-12-07-stk-vae/heldout/clips.parquet
"$py" $C $e/heldout.csv lerp=$V/heldout/clips.parquet:lerp \
  shipped=$V/heldout/clips.parquet:keyframe_rf shipped_corrected=$e/heldout-shipped/clips.parquet:keyframe_rf_corrected \
  anchored=$S:keyframe_rf anchored_corrected=$e/heldout-anchored/clips.parquet:keyframe_rf_corrected \
  anchored_mean8_corrected=$e/heldout-anchored-mean8/clips.parquet:keyframe_rf_mean8_corrected \
  shipped_latent_lerp=$e/heldout-shipped/clips.parquet:lerp_latent \
  shipped_latent_lerp_corrected=$e/heldout-shipped/clips.parquet:lerp_latent_corrected \
  anchored_latent_lerp=$S:lerp_latent anchored_latent_lerp_corrected=$e/heldout-anchored/clips.parquet:lerp_latent_corrected
