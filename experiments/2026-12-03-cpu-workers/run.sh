#!/usr/bin/env bash
# Training steps per second of the small and tiny presets, before and after the two-worker change, in one script:
# the binary of the commit before (ANY4D_OLD) on one device, this commit's binary (ANY4D) on one device and on two
# CPU workers (`--devices flex,flex`, micro-batch halved where the preset has one micro-batch per step). Each cell
# is a short real training run (`train vae` / `train rf` on a 200-clip procedural store); its figure is the median of
# the per-step `steps_per_s` column of metrics.csv after the first step; three repetitions, interleaved.
#
# usage: ANY4D_OLD=/path/to/old/any4d ANY4D=target/release/any4d bash run.sh OUT
set -euo pipefail
OUT=${1:?usage: run.sh OUT}
ANY4D=${ANY4D:-target/release/any4d}
ANY4D_OLD=${ANY4D_OLD:?set ANY4D_OLD to the binary of the commit before the change}
REPS=${REPS:-3}
mkdir -p "$OUT"
STORE=$OUT/store
[ -d "$STORE" ] || "$ANY4D" data synth --clips 200 --seed 7 --max-vertices 1024 --p 128 --out "$STORE" > /dev/null
RUNS=$OUT/runs
CSV=$OUT/runs.csv
echo "preset,binary,devices,micro_batch,rep,steps,median_steps_per_s,wall_s" > "$CSV"

median_sps() { # metrics.csv → median steps_per_s of the rows after the first
  python3 - "$1" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
print(statistics.median(float(r["steps_per_s"]) for r in rows[1:]))
PY
}

# cell PRESET KIND STEPS BIN_LABEL BIN DEVICES MICRO REP EXTRA...
cell() {
  local preset=$1 kind=$2 steps=$3 label=$4 bin=$5 devices=$6 micro=$7 rep=$8
  shift 8
  local name
  name=$(basename "$preset" .toml)-$kind-$label-${devices//,/+}-r$rep
  local dev_args=()
  # The old binary trains on one device without --devices; this one would start a worker per core.
  [ "$label" = "old" ] && [ "$devices" = "flex" ] || dev_args=(--devices "$devices")
  local t0 t1
  t0=$(date +%s.%N)
  "$bin" train "$kind" --config "$preset" --data "$STORE" --runs-dir "$RUNS" --run "$name" "${dev_args[@]}" \
    --set "train.duration={steps=$steps}" --set "train.valid_every=$steps" --set "train.checkpoint_every=$steps" \
    --set "train.micro_batch=$micro" "$@" > "$OUT/$name.log" 2>&1
  t1=$(date +%s.%N)
  local dir
  dir=$(ls -d "$RUNS/$name"-* | tail -1)
  echo "$(basename "$preset" .toml)-$kind,$label,${devices//,/+},$micro,$rep,$steps,$(median_sps "$dir/metrics.csv"),$(echo "$t1 - $t0" | bc)" >> "$CSV"
  tail -1 "$CSV"
}

# A tiny VAE for the tiny RF (trained once, not timed).
TINY_VAE=$RUNS/tiny-vae-base
if [ ! -d "$TINY_VAE" ]; then
  "$ANY4D" train vae --config configs/vae/tiny.toml --data "$STORE" --runs-dir "$RUNS" --run tiny-vae-base \
    --set 'train.duration={steps=20}' > "$OUT/tiny-vae-base.log" 2>&1
  mv "$(ls -d "$RUNS"/tiny-vae-base-* | tail -1)" "$TINY_VAE"
fi

for rep in $(seq 1 "$REPS"); do
  for cfg in "old $ANY4D_OLD flex" "new $ANY4D flex" "new $ANY4D flex,flex"; do
    set -- $cfg
    label=$1 bin=$2 devices=$3
    two=$([ "$devices" = "flex,flex" ] && echo 1 || echo 0)
    cell configs/vae/small.toml vae 30 "$label" "$bin" "$devices" $((two ? 8 : 16)) "$rep"
    cell configs/rf/small.toml rf 40 "$label" "$bin" "$devices" $((two ? 16 : 32)) "$rep" \
      --vae weights/small/vae --set rf.valid_sample_every=0
    cell configs/vae/tiny.toml vae 60 "$label" "$bin" "$devices" 4 "$rep"
    cell configs/rf/tiny.toml rf 60 "$label" "$bin" "$devices" 4 "$rep" --vae "$TINY_VAE" --set rf.valid_sample_every=0
  done
done
echo "wrote $CSV"
