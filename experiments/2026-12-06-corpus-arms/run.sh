#!/usr/bin/env bash
# What each kind of training data buys the small frame-wise VAE at a fixed budget (configs/vae/small.toml, its
# 2,000 steps, trained from scratch): procedural + rigged clips (the rigged-characters experiment's run), the same
# with augmentation, + the real corpus (short looping takes played round, Cube 2's models added), all of it with
# augmentation, and the whole training corpus of scripts/training_corpus.sh (about 49,000 training windows); each
# scored by table 5 (posterior mean) against the shipped VAE on the held-out real store,
# the real corpus's validation split, procedural and rigged validation clips.
#
#   bash experiments/2026-12-06-corpus-arms/run.sh SCRATCH     # ANY4D_BIN=... if not target/release/any4d
#
# SCRATCH (outside the repository) receives the stores and the run folders; the tables land in this folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
mkdir -p "$tmp"
cd "$root"
# Stores: the held-out real store; the real corpus as the earlier experiments built it (its validation split is
# the real-val set) and as scripts/real_corpus.sh builds it now (the training arm's); procedural, rigged, both.
[[ -d $tmp/heldout/store ]] || ANY4D=$bin bash scripts/heldout_corpus.sh "$tmp/heldout"
[[ -d $tmp/rc/store ]] || (git show 1de5fdd:scripts/real_corpus.sh >"$tmp/real_corpus_before.sh" &&
  ANY4D=$bin bash "$tmp/real_corpus_before.sh" "$tmp/rc")
[[ -d $tmp/rc2/store ]] || ANY4D=$bin bash scripts/real_corpus.sh "$tmp/rc2"
[[ -d $tmp/p2k128 ]] || "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/p2k128"
[[ -d $tmp/rig ]] || "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/rig"
if [[ ! -d $tmp/sr ]]; then
  "$bin" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
  "$bin" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
fi
if [[ ! -d $tmp/srr ]]; then
  cp -r "$tmp/sr" "$tmp/srr"
  "$bin" data import "$tmp/rc2/staged" --out "$tmp/srr" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srr_import.log" || [[ $? -eq 2 ]]
fi
[[ -d $tmp/tc/store ]] || ANY4D=$bin bash scripts/training_corpus.sh "$tmp/tc" >"$tmp/tc_build.log"
aug=(--set vae.augment.yaw_degrees=180 --set vae.augment.mirror=0.5 --set 'vae.augment.scale=[0.7,1.3]'
  --set vae.augment.reverse=0.5 --set 'vae.augment.speed=[0.5,1.0]')
# Each arm: train (unless its run folder exists), then table 5 of the shipped VAE (--vae) and the arm (--vae-b) on
# the same windows of each evaluation set.
arm() { # NAME STORE [--set ...]
  local name=$1
  [[ -d $tmp/runs/$name-1 ]] || "$bin" train vae --config configs/vae/small.toml --data "$2" --runs-dir "$tmp/runs" \
    --run "$name" "${@:3}"
  t5() {
    [[ -f $here/table5/$name/$2/clips.parquet ]] && return
    # --out relative to the repository root, so that the summaries name repository paths.
    "$bin" eval run --protocol table5 --data "$1" --vae weights/small/vae --vae-b "$tmp/runs/$name-1" \
      --posterior mean --out "${here#"$root"/}/table5/$name/$2" "${@:3}"
  }
  t5 "$tmp/heldout/store" heldout --split all --clips 63
  t5 "$tmp/rc/store" real-val --clips 100
  t5 "$tmp/p2k128" procedural-val --clips 100
  t5 "$tmp/rig" rigged-val --clips 100
}
arm vae-sr "$tmp/sr"
arm vae-sra "$tmp/sr" "${aug[@]}"
arm vae-srr "$tmp/srr"
arm vae-srra "$tmp/srr" "${aug[@]}"
# The whole training corpus (scripts/training_corpus.sh: 32,000 shape and 25,000 rigged clips + the real corpus);
# its latent statistics from 8,192 of its ~50,000 training windows and its validation on 2,048 of its ~12,500
# validation windows (neither enters table 5).
arm vae-tc "$tmp/tc/store" --set vae.stats_windows=8192 --set vae.valid_windows=2048
python3 "$here/summarise.py"
