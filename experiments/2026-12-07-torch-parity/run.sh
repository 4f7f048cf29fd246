#!/usr/bin/env bash
# any4d ↔ AnimateAnyMesh's PyTorch modules, output for output (docs/method.md §12): each network exported under
# AnimateAnyMesh's names, loaded with load_state_dict(strict=True) and run on any4d's probe inputs; and the other
# way, AnimateAnyMesh's module with PyTorch's own random initialisation saved as safetensors, imported into any4d and
# probed. Networks: the shipped small family (weights/small: RF width 256, frame-wise VAE), the small sequence-wise
# DyMeshVAE (configs/vae/dymesh_small.toml, 2 steps on 8 procedural clips), and the three at the paper's sizes
# (configs/vae/paper.toml, configs/vae/dymesh_paper.toml, configs/rf/paper.toml; 1 step each on 8 procedural clips:
# weights near their initialisation are what is compared, not a trained model).
#
#   AAM=DIR PY=PYTHON bash experiments/2026-12-07-torch-parity/run.sh SCRATCH    # ANY4D_BIN=... if not target/debug/any4d
#   bash scripts/torch_parity.sh DIR SCRATCH    # the same, with a fresh venv of torch from the package registry
#
# DIR is a checkout of github.com/JarrentWu1031/AnimateAnyMesh (nothing of it is committed here); PYTHON has torch,
# einops, numpy and safetensors. SCRATCH (outside the repository) receives stores, runs and exports; results.csv and
# manifest.json land in this folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/debug/any4d}
aam=${AAM:?set AAM to an AnimateAnyMesh checkout}
py=${PY:-python3}
cd "$root"
mkdir -p "$tmp"
parity=scripts/torch_parity.py
csv="$here/results.csv"
echo "network,size,direction,relative,max_abs_diff,max_abs_output,tol,ok" >"$csv"
row() { # NAME SIZE DIRECTION JSON
  "$py" -c 'import json,sys; d=json.loads(sys.argv[4]); print(",".join([sys.argv[1],sys.argv[2],sys.argv[3],
  repr(d["relative"]),repr(d["max_abs_diff"]),repr(d["max_abs_output"]),repr(d["tol"]),str(d["ok"]).lower()]))' \
    "$@" >>"$csv"
}
check() { # NAME SIZE RUN
  local name=$1 size=$2 run=$3 out="$tmp/$1-$2"
  rm -rf "$out"
  mkdir -p "$out"
  "$bin" model export --run "$run" --out "$out/aam" --names animateanymesh
  "$py" "$parity" load --aam "$aam" --export "$out/aam"
  "$bin" model probe --run "$run" --out "$out/probe.safetensors" --seed 0
  row "$name" "$size" any4d-to-torch "$("$py" "$parity" probe --aam "$aam" --export "$out/aam" --probe "$out/probe.safetensors")"
  # PyTorch → any4d: AAM's own initialisation (plus N(0, 0.02) noise), beside the export's side files.
  mkdir -p "$out/torch"
  cp "$out/aam/config.toml" "$out/torch/"
  for f in tokenizer.json vae_run.json text_encoder.safetensors; do
    [[ -f $out/aam/$f ]] && cp "$out/aam/$f" "$out/torch/"
  done
  "$py" "$parity" random --aam "$aam" --export "$out/aam" --out "$out/torch/model.safetensors" --seed 7
  "$bin" model import --from "$out/torch/model.safetensors" --config "$out/aam/config.toml" --names animateanymesh \
    --out "$out/imported"
  "$bin" model probe --run "$out/imported" --out "$out/imported-probe.safetensors" --seed 1
  row "$name" "$size" torch-to-any4d "$("$py" "$parity" probe --aam "$aam" --export "$out/aam" \
    --weights "$out/torch/model.safetensors" --probe "$out/imported-probe.safetensors")"
}
[[ -d $tmp/ds16 ]] || "$bin" data synth --clips 8 --seed 3 --frames 16 --min-vertices 512 --max-vertices 1024 --p 512 \
  --out "$tmp/ds16"
train() { # KIND NAME CONFIG STEPS [extra...]
  local steps=(--set "train.duration={steps = $4}" --set train.batch_size=4 --set train.micro_batch=4
    --set "train.checkpoint_every=$4" --set "train.valid_every=$4")
  [[ -d $tmp/runs/$2-1 ]] || "$bin" train "$1" --config "$3" --data "$tmp/ds16" --runs-dir "$tmp/runs" --run "$2" --backend flex \
    "${steps[@]}" "${@:5}"
}
check mmdit small weights/small/rf
check frame_vae small weights/small/vae
train vae dymesh-small configs/vae/dymesh_small.toml 2
check dymesh_vae small "$tmp/runs/dymesh-small-1"
train vae vae-paper configs/vae/paper.toml 1
check frame_vae paper "$tmp/runs/vae-paper-1"
train vae dymesh-paper configs/vae/dymesh_paper.toml 1
check dymesh_vae paper "$tmp/runs/dymesh-paper-1"
train rf rf-paper configs/rf/paper.toml 1 --vae "$tmp/runs/vae-paper-1" --set rf.valid_sample_every=0
check mmdit paper "$tmp/runs/rf-paper-1"
"$py" - "$here/manifest.json" "$aam" <<'PY'
import json, subprocess, sys, torch
aam = sys.argv[2]
rev = subprocess.run(["git", "-C", aam, "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
manifest = {
    "command": "AAM=DIR PY=PYTHON bash experiments/2026-12-07-torch-parity/run.sh SCRATCH",
    "any4d_commit": subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip(),
    "animateanymesh_commit": rev or "unknown (the checkout has no git metadata; see README.md)",
    "torch": torch.__version__,
    "probe": "model/src/probe.rs: MMDiT B 2, P 64, L 8; VAEs a 256-vertex chain mesh, 64 tokens",
}
json.dump(manifest, open(sys.argv[1], "w"), indent=1)
PY
cat "$csv"
