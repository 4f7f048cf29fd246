#!/usr/bin/env bash
# Training steps per second of the small and tiny presets: the binary of the commit before the first training-speed
# change (ANY4D_OLD, c6eba19: one device, one thread pool) against this commit's binary (ANY4D) as `train` runs by
# default on a CPU (one worker per core), in one script. Each cell is a short real training run (`train vae` /
# `train rf` on a 200-clip procedural store) with the preset's batch; its figure is the median of the per-step
# `steps_per_s` column of metrics.csv after the first step; three repetitions, old and new interleaved.
#
# The old binary reads the presets of its own commit (OLD_COMMIT; they lack the keys added since, such as
# `train.flush_denormals`), the new one this commit's: the same model sizes and batches.
#
# usage: ANY4D_OLD=/path/to/old/any4d ANY4D=target/release/any4d bash run.sh OUT
set -euo pipefail
OUT=${1:?usage: run.sh OUT}
ANY4D=${ANY4D:-target/release/any4d}
ANY4D_OLD=${ANY4D_OLD:?set ANY4D_OLD to the binary of the commit before the change}
REPS=${REPS:-3}
OLD_COMMIT=${OLD_COMMIT:-c6eba19}
mkdir -p "$OUT"
[ -d "$OUT/old" ] || { mkdir -p "$OUT/old" && git archive "$OLD_COMMIT" configs | tar -x -C "$OUT/old"; }
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

# cell PRESET KIND STEPS LABEL BIN MICRO REP EXTRA...: the old binary on its one device; the new one as `train` runs by
# default (one worker per core up to the step's micro-batches: two on this 2-core machine).
cell() {
  local preset=$1 kind=$2 steps=$3 label=$4 bin=$5 micro=$6 rep=$7
  shift 7
  local name
  name=$(basename "$preset" .toml)-$kind-$label-r$rep
  [ "$label" = old ] && preset=$OUT/old/$preset
  local t0 t1
  t0=$(date +%s.%N)
  "$bin" train "$kind" --config "$preset" --data "$STORE" --runs-dir "$RUNS" --run "$name" \
    --set "train.duration={steps=$steps}" --set "train.valid_every=$steps" --set "train.checkpoint_every=$steps" \
    --set "train.micro_batch=$micro" "$@" > "$OUT/$name.log" 2>&1
  t1=$(date +%s.%N)
  local dir devices
  dir=$(ls -d "$RUNS/$name"-* | tail -1)
  devices=$([ "$label" = old ] && echo one || echo default)
  echo "$(basename "$preset" .toml)-$kind,$label,$devices,$micro,$rep,$steps,$(median_sps "$dir/metrics.csv"),$(echo "$t1 - $t0" | bc)" >> "$CSV"
  tail -1 "$CSV"
}

# The VAEs the RFs train on (not timed): written by the old binary, so that both binaries read them.
for size in small tiny; do
  if [ ! -d "$RUNS/$size-vae-base" ]; then
    "$ANY4D_OLD" train vae --config "$OUT/old/configs/vae/$size.toml" --data "$STORE" --runs-dir "$RUNS" --run "$size-vae-base" \
      --set 'train.duration={steps=20}' > "$OUT/$size-vae-base.log" 2>&1
    mv "$(ls -d "$RUNS/$size-vae-base"-* | tail -1)" "$RUNS/$size-vae-base"
  fi
done

# Each binary runs its presets' micro-batches: the old small presets had one micro-batch per step (small VAE 16,
# small RF 32), the new ones split a step into two, one per worker (8 and 16); the tiny presets have two micro-batches
# of 4 in both (the old binary accumulates them on its one device). CELLS picks presets (default: all four).
CELLS=${CELLS:-small-vae small-rf tiny-vae tiny-rf}
want() { [[ " $CELLS " == *" $1 "* ]]; }
for rep in $(seq 1 "$REPS"); do
  for cfg in "old $ANY4D_OLD" "new $ANY4D"; do
    set -- $cfg
    label=$1 bin=$2
    old=$([ "$label" = old ] && echo 1 || echo 0)
    ! want small-vae || cell configs/vae/small.toml vae 30 "$label" "$bin" $((old ? 16 : 8)) "$rep"
    ! want small-rf || cell configs/rf/small.toml rf 40 "$label" "$bin" $((old ? 32 : 16)) "$rep" \
      --vae "$RUNS/small-vae-base" --set rf.valid_sample_every=0
    ! want tiny-vae || cell configs/vae/tiny.toml vae 60 "$label" "$bin" 4 "$rep"
    ! want tiny-rf || cell configs/rf/tiny.toml rf 60 "$label" "$bin" 4 "$rep" \
      --vae "$RUNS/tiny-vae-base" --set rf.valid_sample_every=0
  done
done
echo "wrote $CSV"
