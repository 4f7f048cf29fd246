#!/usr/bin/env bash
# The PyTorch parity check from nothing: a virtual environment with torch, einops, numpy and safetensors from the
# package registry (torch is large, so CI does not do this), then experiments/2026-12-07-torch-parity/run.sh, which
# exports, probes and imports every network both ways and rewrites that folder's results.csv and manifest.json.
# Re-run it when a network changes.
#
#   bash scripts/torch_parity.sh AAM_CHECKOUT SCRATCH
#
# AAM_CHECKOUT is a checkout of github.com/JarrentWu1031/AnimateAnyMesh (nothing of it is committed here); SCRATCH
# (outside the repository) receives the venv, stores, runs and exports. ANY4D_BIN overrides the any4d binary
# (default: target/debug/any4d, built here if missing).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
aam=${1:?usage: torch_parity.sh AAM_CHECKOUT SCRATCH}
tmp=${2:?usage: torch_parity.sh AAM_CHECKOUT SCRATCH}
mkdir -p "$tmp"
venv="$tmp/venv"
if [[ ! -x $venv/bin/python ]]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check torch einops numpy safetensors
fi
cd "$root"
if [[ -z ${ANY4D_BIN:-} && ! -x target/debug/any4d ]]; then
  cargo build --locked
fi
AAM=$aam PY="$venv/bin/python" bash experiments/2026-12-07-torch-parity/run.sh "$tmp/work"
