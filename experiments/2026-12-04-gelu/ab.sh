#!/usr/bin/env bash
# Before/after timing of the host GELU (docs/method.md §11) in one script, alternating the two release builds,
# three rounds, on the otherwise idle 2-core CPU. BEFORE: a build of the commit before the change; AFTER: with it.
# Writes logs/<what>-<binary>-<round>.txt; summarise.py reads them into steps.csv.
set -euo pipefail
before=${1:?usage: ab.sh BEFORE_BIN AFTER_BIN DATA}; after=${2:?}; data=${3:?}
here=$(cd "$(dirname "$0")" && pwd); root=$(cd "$here/../.." && pwd)
cd "$root"; mkdir -p "$here/logs"
for round in 1 2 3; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        # The small RF's training step (one device, one micro-batch of 16 clips, P = 128 tokens, random latents).
        "$bin" bench train --config configs/rf/small.toml --backends flex --tokens 128 --steps 8 \
            > "$here/logs/rf-train-$v-$round.txt" 2>&1
        # The small VAE's training step on the store (the preset's batch).
        "$bin" bench train --config configs/vae/small.toml --data "$data" --backends flex --steps 6 \
            > "$here/logs/vae-train-$v-$round.txt" 2>&1
        # Encode → 16-point midpoint sampling → decode of one 16-frame clip at the small sizes.
        "$bin" bench sample --rf-config configs/rf/small.toml --vae-config configs/vae/small.toml --vertices 1024 \
            --frames 16 --reps 3 --n-grid 16 --out "$here/logs/sample-$v-$round" > "$here/logs/sample-$v-$round.txt" 2>&1
    done
done
