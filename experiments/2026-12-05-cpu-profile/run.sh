#!/usr/bin/env bash
# The paper-size networks against AnimateAnyMesh's PyTorch modules, and where each side's time goes.
#   bash run.sh ANY4D AAM_DIR
# ANY4D: a release build of the repository's binary; AAM_DIR: an AnimateAnyMesh checkout (networks/dymeshvae.py).
# Needs python3 with torch and einops, and perf. Writes, in this folder:
#   logs/vs-torch-t{1,2}-r{1,2,3}.txt  three rounds, each at 1 then 2 threads (`bench model --torch-reference`);
#   logs/profiled-t{1,2}.txt, share-t{1,2}.csv  one perf profile per thread count (DWARF stacks, 199 Hz), split
#                                      by network and kind of work (share.py);
#   torch-profile-t{1,2}.txt, torch-profile-t1-math.txt  PyTorch's RF step by operator (torch_profile.py);
#   ceiling.csv, torch-config.txt      the CPU's matrix-product rate as PyTorch reaches it (ceiling.py), and the
#                                      BLAS that PyTorch was built with;
#   summary.csv                        all of it per network and thread count (summarise.py).
set -euo pipefail
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
ANY4D=$(realpath "$1")
AAM=$(realpath "$2")
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$here/logs"
cd "$here/../.."
for r in 1 2 3; do
  for t in 1 2; do
    "$ANY4D" bench model --size paper --batch 1 --iters 3 --threads "$t" --torch-reference "$AAM" \
      > "$here/logs/vs-torch-t$t-r$r.txt" 2>&1
  done
done
for t in 1 2; do
  perf record -q -F 199 --call-graph dwarf,16384 -o "$scratch/perf.data" -- \
    "$ANY4D" bench model --size paper --batch 1 --iters 6 --threads "$t" > "$here/logs/profiled-t$t.txt" 2>&1
  perf script -i "$scratch/perf.data" -F time,ip,sym > "$scratch/stacks-t$t.txt" 2>/dev/null
  python3 "$here/share.py" "$scratch/stacks-t$t.txt" "$here/logs/profiled-t$t.txt" > "$here/share-t$t.csv"
done
python3 "$here/torch_profile.py" "$AAM" 1 > "$here/torch-profile-t1.txt" 2>&1
python3 "$here/torch_profile.py" "$AAM" 1 math > "$here/torch-profile-t1-math.txt" 2>&1
python3 "$here/torch_profile.py" "$AAM" 2 > "$here/torch-profile-t2.txt" 2>&1
python3 "$here/ceiling.py" > "$here/ceiling.csv"
python3 - > "$here/torch-config.txt" <<'PY'
import re
import torch
cfg = torch.__config__.show()
print(f"torch {torch.__version__}")
for key in ("BLAS_INFO", "LAPACK_INFO", "USE_MKL", "USE_MKLDNN"):
    m = re.search(rf"{key}=([^,]+)", cfg)
    print(f"{key}={m.group(1) if m else '?'}")
for line in cfg.splitlines():
    if "CPU capability" in line or "MKL-DNN" in line or "Math Kernel Library" in line:
        print(line.strip())
PY
python3 "$here/summarise.py"
