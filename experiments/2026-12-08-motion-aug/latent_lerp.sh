#!/usr/bin/env bash
# The latent-lerp target of the real-characters work (latent lerp ≤ 1.1 × vertex lerp held out): table 1 on the
# held-out store whole with lerp, lerp_latent and vae_oracle (deterministic rows, one seed) through the separating
# arm's VAE and through vae-motion15; summarise.py pairs each latent row with lerp window by window.
#
#   bash experiments/2026-12-08-motion-aug/latent_lerp.sh HELDOUT ARM_RUN MOTION_RUN
#
# ARM_RUN: the run folder of ../2026-12-07-vae-repro's arm.sh; MOTION_RUN: run.sh's. ANY4D_BIN as in run.sh.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
usage="usage: latent_lerp.sh HELDOUT ARM_RUN MOTION_RUN"
heldout=${1:?$usage}
arm=${2:?$usage}
motion=${3:?$usage}
bin=${ANY4D_BIN:-$root/target/release/any4d}
cd "$root"
t1() { # NAME VAE
  local out=${here#"$root"/}/table1/$1
  [[ -f $out/clips.parquet ]] && return
  "$bin" eval run --protocol table1 --data "$heldout" --split all --clips 63 --methods lerp,lerp_latent,vae_oracle \
    --vae "$2" --export 0 --no-progress --out "$out"
}
t1 separating-arm "$arm"
t1 motion15 "$motion"
python3 "$here/summarise.py"
