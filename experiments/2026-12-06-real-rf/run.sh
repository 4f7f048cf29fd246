#!/usr/bin/env bash
# Does the keyframe RF complete real characters better than interpolation once its VAE and its own training data
# hold real motion? The small RF preset (configs/rf/small.toml, unchanged: 9,000 steps of batch 16) trained from
# scratch on procedural + rigged + real clips, on the latents of the whole-corpus VAE of ../2026-12-06-corpus-arms
# (`vae-tc`), scored against lerp, latent lerp, the VAE's own floor and the shipped family on the held-out real store,
# the real corpus's validation split and procedural validation clips, on the windows, keyframes and seeds of the
# shipped family's committed rows (so every row is paired window by window).
#
#   bash experiments/2026-12-06-real-rf/run.sh SCRATCH      # ANY4D_BIN=... if not target/release/any4d
#
# SCRATCH is the corpus-arms scratch folder (its run.sh builds the stores and the `vae-tc` VAE there); the tables
# land in this folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
cd "$root"
vae=$tmp/runs/vae-tc-1
[[ -d $vae/checkpoints ]] || { echo "no $vae: run experiments/2026-12-06-corpus-arms/run.sh $tmp first" >&2; exit 1; }
# The training store: 2,000 procedural shape + 2,000 rigged clips (seed 666) + the real corpus staged by
# scripts/training_corpus.sh (16-frame windows every 8 frames, short looping takes played round).
if [[ ! -d $tmp/srr ]]; then
  "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/srr"
  "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/srr"
  "$bin" data import "$tmp/tc/real/staged" --out "$tmp/srr" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srr_import.log" || [[ $? -eq 2 ]]
fi
run=$tmp/rfruns/rf-tc-srr-1
[[ -f $run/checkpoints/step_9000/model.bpk ]] ||
  "$bin" train rf --config configs/rf/small.toml --vae "$vae" --data "$tmp/srr" --runs-dir "$tmp/rfruns" \
    --run rf-tc-srr
for f in config.toml log.txt metrics.csv valid.csv samples.csv loss.png; do
  [[ -f $run/$f ]] && mkdir -p "$here/run" && cp "$run/$f" "$here/run/"
done
V=experiments/2026-12-05-vae2000-family
S=experiments/2026-12-04-rf-scale
e=${here#"$root"/}
t1() { # OUT DATA [args...]
  [[ -f $here/$1/clips.parquet ]] && return
  "$bin" eval run --protocol table1 --data "$2" --out "$e/$1" --rf "$run" --n-grid 16 --export 0 "${@:3}"
}
t1 heldout "$tmp/heldout/store" --split all --manifest $V/heldout/manifest.json \
  --methods keyframe_rf,lerp_latent,vae_oracle
# The real corpus's validation split as the earlier experiments built it (scripts/real_corpus.sh of 1de5fdd, rebuilt
# by the corpus-arms script: other windows than ../2026-12-05-real-finetune's draw), 50 windows drawn afresh; the
# shipped RF scored on the same windows.
t1 real-val "$tmp/rc/store" --clips 50 --seeds 42 --methods keyframe_rf,lerp_latent,lerp
[[ -f $here/real-val-shipped/clips.parquet ]] ||
  "$bin" eval run --protocol table1 --data "$tmp/rc/store" --manifest "$e/real-val/manifest.json" \
    --out "$e/real-val-shipped" --rf weights/small/rf --methods keyframe_rf --n-grid 16 --export 0
t1 procedural-s42 "$tmp/p2k128" --manifest $S/manifest.json --methods keyframe_rf,lerp_latent,lerp
t1 procedural-s43-44 "$tmp/p2k128" --manifest $S/manifest-other-seeds.json --methods keyframe_rf,lerp
python3 "$here/compare.py" "$here/heldout-vs-shipped.csv" \
  shipped=$V/heldout/clips.parquet:keyframe_rf ours_real=$e/heldout/clips.parquet:keyframe_rf \
  lerp=$V/heldout/clips.parquet:lerp latent_lerp=$e/heldout/clips.parquet:lerp_latent \
  vae_oracle=$e/heldout/clips.parquet:vae_oracle baseline_shipped=$V/heldout/clips.parquet:replacement_rf
python3 "$here/compare.py" "$here/real-val-vs-shipped.csv" \
  shipped=$e/real-val-shipped/clips.parquet:keyframe_rf ours_real=$e/real-val/clips.parquet:keyframe_rf \
  lerp=$e/real-val/clips.parquet:lerp latent_lerp=$e/real-val/clips.parquet:lerp_latent
python3 "$here/compare.py" "$here/procedural-vs-shipped.csv" \
  shipped=$V/table1-s42/clips.parquet+$V/table1-s43-44/clips.parquet:keyframe_rf \
  ours_real=$e/procedural-s42/clips.parquet+$e/procedural-s43-44/clips.parquet:keyframe_rf \
  lerp=$e/procedural-s42/clips.parquet+$e/procedural-s43-44/clips.parquet:lerp \
  baseline_shipped=$V/table1-baseline-s42/clips.parquet+$V/table1-baseline-s43-44/clips.parquet:replacement_rf
python3 "$here/plot.py"
