#!/usr/bin/env bash
# Sharded stores on this machine: import throughput of one process against shards written by two at once, read
# throughput of a one-file store against the same clips as shards, and the resident memory of training on a small
# and a large sharded store (docs/data.md "Sharded stores", docs/training.md "Data order on a sharded store").
#
#   bash experiments/2026-12-07-sharded-store/run.sh SCRATCH   # ANY4D_BIN=... if not target/release/any4d
#   SMALL=N LARGE_SHARDS=M (clips of the small store; shards of SMALL clips each in the large one)
#
# Writes measurements.csv (one row per measured command: what, clips, bytes, seconds, peak RSS) here. SCRATCH needs
# about (LARGE_SHARDS + 2) × the small store's bytes free.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: run.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
small=${SMALL:-12500}
large_shards=${LARGE_SHARDS:-11}
cd "$root"
mkdir -p "$tmp"
out=$here/measurements.csv
echo "what,processes,threads_per_process,clips,bytes,seconds,peak_rss_mb" >"$out"
# One synth of the small store's clips: shapes family, P = 128, up to 1,024 vertices, 16 frames.
synth=(data synth --clips "$small" --p 128 --max-vertices 1024)
# `timed WHAT PROCS THREADS DIR CMD...`: run CMD under /usr/bin/time, append a row (bytes = clips.bin files in DIR).
timed() {
  local what=$1 procs=$2 threads=$3 dir=$4
  shift 4
  local log=$tmp/time-$what.txt
  /usr/bin/time -f "%e %M" -o "$log" "$@" >"$tmp/out-$what.txt" 2>&1
  row "$what" "$procs" "$threads" "$dir" "$(cut -d' ' -f1 "$log")" "$(cut -d' ' -f2 "$log")"
}
row() {
  local bytes clips
  bytes=$(find "$4" -name clips.bin -printf '%s\n' | awk '{s += $1} END {printf "%.0f", s}')
  clips=$("$bin" data inspect "$4" --format json | python3 -c 'import json, sys; print(json.load(sys.stdin)["ok"])')
  echo "$1,$2,$3,$clips,$bytes,$5,$(($6 / 1024))" >>"$out"
}
# 1. Import: one process, then two shard processes at once (wall time of both), with all cores and with one thread
#    per process (RAYON_NUM_THREADS=1: what each of N machines would do alone).
for threads in 0 1; do
  env=()
  [[ $threads == 1 ]] && env=(env RAYON_NUM_THREADS=1)
  one=$tmp/one-t$threads
  rm -rf "$one"
  timed "import-1proc-t$threads" 1 "$threads" "$one" "${env[@]}" "$bin" "${synth[@]}" --seed 11 --out "$one"
  two=$tmp/two-t$threads
  rm -rf "$two"
  start=$(date +%s.%N)
  "${env[@]}" "$bin" "${synth[@]}" --seed 11 --shard 0/2 --out "$two/shard-0" >/dev/null &
  "${env[@]}" "$bin" "${synth[@]}" --seed 11 --shard 1/2 --out "$two/shard-1" >/dev/null
  wait
  end=$(date +%s.%N)
  "$bin" data merge "$two" "$two/shard-0" "$two/shard-1" >/dev/null
  row "import-2proc-t$threads" 2 "$threads" "$two" "$(echo "$end - $start" | bc)" 0
  [[ $threads == 1 ]] && rm -rf "$one"
done
# 2. Reading: every clip checksummed and decoded (`data verify`), the one-file store against its two shards.
timed read-onefile 1 0 "$tmp/one-t0" "$bin" data verify "$tmp/one-t0"
timed read-sharded 1 0 "$tmp/two-t0" "$bin" data verify "$tmp/two-t0"
rm -rf "$tmp/two-t1"
# 3. Training on the small store, one-file and sharded: the tiny VAE preset with 128 tokens, 200 steps, no
#    validation before the end; peak resident memory and wall time.
train=(train vae --config configs/vae/tiny.toml --set train.duration.steps=200 --set train.valid_every=100000
  --set train.checkpoint_every=100000 --set vae.tokens=128 --set vae.stats_windows=256 --set vae.valid_windows=64
  --runs-dir "$tmp/runs")
rm -rf "$tmp/runs"
timed train-small-onefile 1 0 "$tmp/one-t0" "$bin" "${train[@]}" --data "$tmp/one-t0" --run small-onefile
timed train-small-sharded 1 0 "$tmp/two-t0" "$bin" "${train[@]}" --data "$tmp/two-t0" --run small-sharded
rm -rf "$tmp/one-t0"
# 4. A large store: LARGE_SHARDS shards of the small store's size (other seeds), two written at a time; the same
#    training on it.
big=$tmp/large
mkdir -p "$big"
start=$(date +%s.%N)
for ((k = 0; k < large_shards; k += 2)); do
  for j in $k $((k + 1)); do
    ((j < large_shards)) || continue
    [[ -f $big/shard-$j/clips.bin ]] || "$bin" "${synth[@]}" --seed $((100 + j)) --out "$big/shard-$j" >/dev/null &
  done
  wait
done
"$bin" data merge --max-shard-bytes 3GB "$big" "$big"/shard-* >/dev/null
end=$(date +%s.%N)
row import-large-2proc 2 0 "$big" "$(echo "$end - $start" | bc)" 0
timed train-large-sharded 1 0 "$big" "$bin" "${train[@]}" --data "$big" --run large-sharded
# Reading it whole, more than the page cache holds: every shard's checksum, then every clip.
timed read-large-sharded 1 0 "$big" "$bin" data verify "$big"
cat "$out"
