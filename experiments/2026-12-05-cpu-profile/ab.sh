#!/usr/bin/env bash
# The paper-size networks before and after the CPU speed changes since ebd9d8d, on one machine in one script:
# OLD, a release build of ebd9d8d (the commit before gemm's AVX-512 kernels), and NEW, a release build of the current
# code (bf19b4a in the committed run), each against AnimateAnyMesh's PyTorch modules, alternating.
#   bash ab.sh OLD NEW AAM_DIR
# Writes logs/ab-{old,new}-t{1,2}-r{1,2,3}.txt and ab.csv (ab_summarise.py). Each binary uses its own copy of
# scripts/bench_torch_reference.py (the RF, VAE and DyMeshVAE shapes are the same in both).
set -euo pipefail
OLD=$(realpath "$1")
NEW=$(realpath "$2")
AAM=$(realpath "$3")
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$here/logs"
for r in 1 2 3; do
  for t in 1 2; do
    for which in old new; do
      bin=$OLD
      [ "$which" = new ] && bin=$NEW
      "$bin" bench model --size paper --batch 1 --iters 3 --threads "$t" --torch-reference "$AAM" \
        > "$here/logs/ab-$which-t$t-r$r.txt" 2>&1
    done
  done
done
python3 "$here/ab_summarise.py"
