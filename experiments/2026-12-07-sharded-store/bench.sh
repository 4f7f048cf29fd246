#!/usr/bin/env bash
# The streaming reader and the RF's latent files, in one run (docs/data.md "Sharded stores", docs/training.md
# "Latents on disk"):
# 1. `any4d bench store` on the one-file store, the same clips as 2 shards, and that sharded store in S3 (moto's
#    local server, PyPI `moto[server]`) read cold and cached: training-order reads, alternating rounds -> bench_store.csv
# 2. what the small RF consumes: `any4d bench train --config configs/rf/small.toml` (steps/s × batch 16) -> rf_consumes.txt
# 3. latent files of a 2-shard store by the shipped small VAE: one process for both shards against two processes
#    at once, one shard each, one thread per process -> latents.csv; then 100 small-RF steps on those files against
#    the same steps with the in-memory cache (start-up and steps/s from each run's log and metrics.csv).
#
#   bash experiments/2026-12-07-sharded-store/bench.sh SCRATCH   # ANY4D_BIN=... if not target/release/any4d
#   SMALL=N (clips of the read stores, default 12,500), LAT=N (clips of the latent-file store, default 2,000)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
tmp=${1:?usage: bench.sh SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
small=${SMALL:-12500}
lat=${LAT:-2000}
port=${PORT:-5124}
cd "$root"
mkdir -p "$tmp" "$here/logs"
synth=(data synth --p 128 --max-vertices 1024 --seed 11)

# 1. Stores: the one-file store and the same clips as two shards.
[[ -d $tmp/one ]] || "$bin" "${synth[@]}" --clips "$small" --out "$tmp/one" >/dev/null
if [[ ! -f $tmp/two/manifest.json ]]; then
  for k in 0 1; do "$bin" "${synth[@]}" --clips "$small" --shard $k/2 --out "$tmp/two/shard-$k" >/dev/null; done
  "$bin" data merge "$tmp/two" "$tmp/two/shard-0" "$tmp/two/shard-1" >/dev/null
fi
moto_server -H 127.0.0.1 -p "$port" >"$tmp/moto.log" 2>&1 &
moto=$!
trap 'kill $moto' EXIT
sleep 2
export AWS_ENDPOINT_URL=http://127.0.0.1:$port AWS_ALLOW_HTTP=true AWS_ACCESS_KEY_ID=test AWS_SECRET_ACCESS_KEY=test
export AWS_REGION=us-east-1 AWS_DEFAULT_REGION=us-east-1
python3 scripts/upload_store.py "$AWS_ENDPOINT_URL" clips store "$tmp/two" >/dev/null
"$bin" bench store "$tmp/one" "$tmp/two" s3://clips/store --rounds 3 --csv "$here/bench_store.csv" |
  tee "$here/logs/bench-store.txt"
kill $moto
trap - EXIT

# 2. What the small RF consumes per second (random latents, the preset's batch).
"$bin" bench train --config configs/rf/small.toml --tokens 128 --micro-batch 16 --backends flex 2>&1 | tee "$here/rf_consumes.txt"

# 3. Latent files: one process, both shards (1 thread), then two processes at once, one shard each (1 thread each).
[[ -f $tmp/lat/manifest.json ]] || {
  for k in 0 1; do "$bin" "${synth[@]}" --clips "$lat" --shard $k/2 --out "$tmp/lat/shard-$k" >/dev/null; done
  "$bin" data merge "$tmp/lat" "$tmp/lat/shard-0" "$tmp/lat/shard-1" >/dev/null
}
vae=weights/small/vae
echo "what,processes,threads_per_process,clips,seconds" >"$here/latents.csv"
rm -rf "$tmp/lat1" "$tmp/lat2"
start=$(date +%s.%N)
RAYON_NUM_THREADS=1 "$bin" train latents --vae $vae --data "$tmp/lat" --latents "$tmp/lat1" 2>"$here/logs/latents-1proc.txt"
echo "encode-1proc,1,1,$lat,$(echo "$(date +%s.%N) - $start" | bc)" >>"$here/latents.csv"
start=$(date +%s.%N)
RAYON_NUM_THREADS=1 "$bin" train latents --vae $vae --data "$tmp/lat" --latents "$tmp/lat2" --shard 0 2>"$here/logs/latents-2proc-0.txt" &
RAYON_NUM_THREADS=1 "$bin" train latents --vae $vae --data "$tmp/lat" --latents "$tmp/lat2" --shard 1 2>"$here/logs/latents-2proc-1.txt"
wait
echo "encode-2proc,2,1,$lat,$(echo "$(date +%s.%N) - $start" | bc)" >>"$here/latents.csv"
cmp "$tmp/lat1/shard-00000.latents" "$tmp/lat2/shard-00000.latents"
cmp "$tmp/lat1/shard-00001.latents" "$tmp/lat2/shard-00001.latents"
echo "the files of one process and of two are byte for byte the same" >>"$here/logs/latents-2proc-1.txt"

# The small RF for 100 steps on the latent files (reused) and with the in-memory cache (encoded at start).
rm -rf "$tmp/runs"
for cache in disk memory; do
  start=$(date +%s.%N)
  "$bin" train rf --config configs/rf/small.toml --vae $vae --data "$tmp/lat" --latents "$tmp/lat1" \
    --set "rf.latent_cache=\"$cache\"" --set 'train.duration={steps=100}' --set rf.valid_sample_every=0 \
    --set train.checkpoint_every=100 --set train.valid_every=100 --runs-dir "$tmp/runs" --run "rf-$cache" \
    >"$here/logs/rf-$cache.txt" 2>&1
  echo "rf-100-steps-$cache,1,0,$lat,$(echo "$(date +%s.%N) - $start" | bc)" >>"$here/latents.csv"
  cp "$tmp/runs/rf-$cache-1/log.txt" "$here/logs/rf-$cache-log.txt"
  cp "$tmp/runs/rf-$cache-1/metrics.csv" "$here/logs/rf-$cache-metrics.csv"
done
cat "$here/latents.csv"
