#!/usr/bin/env bash
# The tables of README.md from the committed clips.parquet files: real-val.csv, heldout.csv, procedural-val.csv
# (reference row: the procedural RF at step 1,000), their *-vs-both.csv twins (reference: the both RF), summary.csv and
# rmse_vs_kx.png. usage: bash compare_all.sh (numpy, pyarrow and matplotlib)
set -euo pipefail
cd "$(dirname "$0")"
python3 ../2026-12-02-anchor/compare.py real-val.csv procedural1000=real-val/procedural-s1000/clips.parquet:keyframe_rf \
  real1000=real-val/real-s1000/clips.parquet:keyframe_rf both1000=real-val/both-s1000/clips.parquet:keyframe_rf \
  procedural=real-val/procedural/clips.parquet:keyframe_rf baseline=real-val/baseline/clips.parquet:replacement_rf \
  latentlerp=real-val/latent-lerp/clips.parquet:lerp_latent lerp=real-val/procedural/clips.parquet:lerp --seeds 42
python3 ../2026-12-02-anchor/compare.py heldout.csv procedural1000=heldout/procedural-s1000/clips.parquet:keyframe_rf \
  real1000=heldout/real-s1000/clips.parquet:keyframe_rf both1000=heldout/both-s1000/clips.parquet:keyframe_rf \
  procedural=../2026-12-03-first-last/heldout/clips.parquet:keyframe_rf baseline=heldout/baseline/clips.parquet:replacement_rf \
  latentlerp=heldout/latent-lerp/clips.parquet:lerp_latent lerp=heldout/procedural-s1000/clips.parquet:lerp --seeds 42
python3 ../2026-12-02-anchor/compare.py procedural-val.csv \
  procedural1000=procedural-val/procedural-s1000/clips.parquet:keyframe_rf \
  real1000=procedural-val/real-s1000/clips.parquet:keyframe_rf both1000=procedural-val/both-s1000/clips.parquet:keyframe_rf \
  procedural=../2026-12-03-first-last/table1-s1500/clips.parquet:keyframe_rf baseline=procedural-val/baseline/clips.parquet:replacement_rf \
  latentlerp=procedural-val/latent-lerp/clips.parquet:lerp_latent lerp=procedural-val/procedural-s1000/clips.parquet:lerp \
  --seeds 42
python3 plot.py
for set in real-val heldout procedural-val; do
  lerp=$set/procedural-s1000/clips.parquet:lerp; [[ $set == real-val ]] && lerp=real-val/procedural/clips.parquet:lerp
  python3 ../2026-12-02-anchor/compare.py $set-vs-both.csv both1000=$set/both-s1000/clips.parquet:keyframe_rf \
    procedural1000=$set/procedural-s1000/clips.parquet:keyframe_rf real1000=$set/real-s1000/clips.parquet:keyframe_rf \
    lerp=$lerp --seeds 42 > /dev/null
done
