#!/usr/bin/env bash
# Does today's code train the corpus-arms' VAEs exactly as their binaries did? Each arm's committed config
# (experiments/2026-12-06-corpus-arms/runs/ARM/config.toml) is trained again from scratch on its store, rebuilt with
# today's binary, for the first STEPS steps (the warm-up's learning rates do not depend on the run's length), and
# compare.py sets the per-step losses beside the committed metrics.csv. Equal losses mean equal code and data for
# those steps; the first step that differs says when (and the store summary says whether the data differ).
#
#   bash experiments/2026-12-07-vae-repro/run.sh SCRATCH REAL LABEL [STEPS]
#
# ANY4D_BIN: the binary that imports and trains (default target/release/any4d); ANY4D_SYNTH_BIN: the one that
# generates the procedural and rigged clips (default ANY4D_BIN). Stores go to SCRATCH/LABEL, results to runs/LABEL.
#
# REAL: a folder holding `staged/` (scripts/real_corpus.sh's staging). The real store leaves out the six staging
# folders added after the corpus-arms run: SuperTuxKart, the four packages of 3fcd98e and the mocap retargeted onto
# Cube 2's snout (cube2-data+assimp-testmodels), as vae-srr's store had none of them.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
usage="usage: run.sh SCRATCH REAL LABEL [STEPS]"
label=${3:?$usage}
tmp=${1:?$usage}/$label
real=${2:?$usage}
steps=${4:-40}
bin=${ANY4D_BIN:-$root/target/release/any4d}
synth=${ANY4D_SYNTH_BIN:-$bin}
arms=$root/experiments/2026-12-06-corpus-arms/runs
mkdir -p "$tmp"
cd "$root"
if [[ ! -d $tmp/sr ]]; then
  "$synth" data synth --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
  "$synth" data synth --family rigged --clips 2000 --seed 666 --max-vertices 1024 --p 128 --out "$tmp/sr"
fi
if [[ ! -d $tmp/srr ]]; then
  mkdir -p "$tmp/staged-old"
  for d in "$real"/staged/*; do
    case $(basename "$d") in
      supertuxkart-data | gambas3-examples | blobandconquer-data | castle-game-engine-doc | minetest-mod-homedecor | \
        cube2-data+assimp-testmodels) ;;
      *) ln -sfn "$d" "$tmp/staged-old/" ;;
    esac
  done
  cp -r "$tmp/sr" "$tmp/srr"
  "$bin" data import "$tmp/staged-old" --out "$tmp/srr" --frames 16 --stride 8 --p 128 --min-vertices 128 \
    --max-vertices 4096 --loop-short >"$tmp/srr_import.log" || [[ $? -eq 2 ]]
fi
mkdir -p "$here/stores/$label"
"$bin" data inspect "$tmp/sr" | sed -E "s#$tmp/##g; s#/[^ ]*/(staged[^/]*/)#\1#g" >"$here/stores/$label/sr.txt"
"$bin" data inspect "$tmp/srr" | sed -E "s#$tmp/##g; s#/[^ ]*/(staged[^/]*/)#\1#g" >"$here/stores/$label/srr.txt"
arm() { # ARM STORE
  local name=$1 store=$2
  if [[ ! -f $tmp/runs/$name-1/metrics.csv ]] || (($(wc -l <"$tmp/runs/$name-1/metrics.csv") <= steps)); then
    rm -rf "$tmp/runs/$name-1"
    # The committed config, with latent statistics and validation on 64 windows (after the steps compared).
    sed 's/^tokens = 128$/tokens = 128\nstats_windows = 64\nvalid_windows = 64/' "$arms/$name/config.toml" \
      >"$tmp/$name.toml"
    "$bin" train vae --config "$tmp/$name.toml" --data "$store" --runs-dir "$tmp/runs" --run "$name" \
      --set train.duration.steps="$steps"
  fi
  mkdir -p "$here/runs/$label/$name"
  cp "$tmp/runs/$name-1"/{config.toml,metrics.csv} "$here/runs/$label/$name/"
  sed "s#$tmp/##g" "$tmp/runs/$name-1/log.txt" >"$here/runs/$label/$name/log.txt"
}
arm vae-sr "$tmp/sr"
arm vae-sra "$tmp/sr"
arm vae-srr "$tmp/srr"
arm vae-srra "$tmp/srr"
python3 "$here/compare.py"
