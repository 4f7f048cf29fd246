#!/usr/bin/env bash
# Scene conditioning at small scale (docs/method.md §4.12): does telling the small keyframe RF the scene — the
# occupancy grid's tokens (S3), the keyframes' anchor offsets (S4), or both — complete rigged characters in procedural
# scenes with fewer collisions or lower error than the same RF told nothing? Four RFs trained alike on one store, a
# scene store of another generator seed scored whole, 3 sampler seeds.
#
#   bash experiments/2026-12-07-scene-rf/run.sh SCRATCH     # ANY4D_BIN=... if not target/release/any4d; STEPS=...
#
# The shipped VAE (weights/small/vae, frozen) encodes every store. Run from anywhere; tables land here.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
steps=${STEPS:-1000}
cd "$root"
e=${here#"$root"/}
# Training: 2,000 rigged characters in scenes (seed 7); test: 100 of another seed, never trained on.
[[ -d $tmp/train ]] || "$bin" data synth --family rigged --scenes --clips 2000 --seed 7 --max-vertices 1024 --p 128 \
  --out "$tmp/train"
[[ -d $tmp/test ]] || "$bin" data synth --family rigged --scenes --clips 100 --seed 9001 --max-vertices 1024 --p 128 \
  --out "$tmp/test"
# The small preset at $steps steps (its schedule follows the duration), validation samples off; one variant each.
declare -A sets=(
  [none]="--set model.scene.global=false --set model.scene.local=false"
  [global]="--set model.scene.global=true --set model.scene.local=false"
  [local]="--set model.scene.global=false --set model.scene.local=true"
  [both]="--set model.scene.global=true --set model.scene.local=true"
)
for v in none both global local; do
  run=$tmp/runs/rf-$v-1
  if [[ ! -f $run/checkpoints/step_$steps/model.bpk ]]; then
    rm -rf "$run"
    # shellcheck disable=SC2086
    "$bin" train rf --config configs/rf/small.toml --vae weights/small/vae --data "$tmp/train" --runs-dir "$tmp/runs" \
      --run "rf-$v" --set train.duration.steps=$steps --set rf.valid_sample_every=0 ${sets[$v]} >"$tmp/train-$v.log" 2>&1
  fi
  mkdir -p "$here/runs/$v"
  for f in config.toml metrics.csv valid.csv loss.png; do
    [[ -f $run/$f ]] && cp "$run/$f" "$here/runs/$v/"
  done
  if [[ ! -f $here/test-$v/clips.parquet ]]; then
    if [[ $v == none ]]; then
      methods=(--methods lerp,lerp_latent,keyframe_rf --clips 100 --seeds 42,43,44)
    else # the windows, keyframes and seeds of the first table
      methods=(--methods keyframe_rf --manifest "$e/test-none/manifest.json")
    fi
    "$bin" eval run --protocol table1 --data "$tmp/test" --split all --rf "$run" --n-grid 16 --export 0 \
      --no-progress --out "$e/test-$v" "${methods[@]}"
  fi
done
"${PYTHON:-python3}" "$here/compare.py" "$here/results.csv" none="$e/test-none/clips.parquet:keyframe_rf" \
  both="$e/test-both/clips.parquet:keyframe_rf" global="$e/test-global/clips.parquet:keyframe_rf" \
  local="$e/test-local/clips.parquet:keyframe_rf" lerp="$e/test-none/clips.parquet:lerp" \
  latent_lerp="$e/test-none/clips.parquet:lerp_latent"
