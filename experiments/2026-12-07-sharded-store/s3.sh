#!/usr/bin/env bash
# Reading a sharded store from S3 (moto's local S3 server, PyPI `moto[server]`) against reading it from local disk,
# in one run: `data verify` of the local store, then of its copy in S3 through an empty cache (fetch + verify), then
# again with the cache filled (manifest fetch + verify). Appends rows to measurements.csv.
#
#   bash experiments/2026-12-07-sharded-store/s3.sh STORE SCRATCH   # STORE: a sharded store folder (run.sh's two-t0)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
store=${1:?usage: s3.sh STORE SCRATCH}
tmp=${2:?usage: s3.sh STORE SCRATCH}
bin=${ANY4D_BIN:-$root/target/release/any4d}
out=$here/measurements.csv
port=${PORT:-5123}
mkdir -p "$tmp"
moto_server -H 127.0.0.1 -p "$port" >"$tmp/moto.log" 2>&1 &
moto=$!
trap 'kill $moto' EXIT
export AWS_ENDPOINT_URL=http://127.0.0.1:$port AWS_ALLOW_HTTP=true AWS_ACCESS_KEY_ID=test AWS_SECRET_ACCESS_KEY=test
export AWS_REGION=us-east-1 AWS_DEFAULT_REGION=us-east-1 ANY4D_CACHE=$tmp/cache
python3 "$root/scripts/upload_store.py" "$AWS_ENDPOINT_URL" clips store "$store"
rm -rf "$tmp/cache"
bytes=$(find "$store" -name clips.bin -printf '%s\n' | awk '{s += $1} END {printf "%.0f", s}')
clips=$("$bin" data inspect "$store" --format json | python3 -c 'import json, sys; print(json.load(sys.stdin)["ok"])')
for what in read-sharded-local:"$store" read-s3-cold:s3://clips/store read-s3-cached:s3://clips/store; do
  /usr/bin/time -f "%e %M" -o "$tmp/time.txt" "$bin" data verify "${what#*:}" >"$tmp/out-${what%%:*}.txt" 2>&1
  echo "${what%%:*},1,0,$clips,$bytes,$(cut -d' ' -f1 "$tmp/time.txt"),$(($(cut -d' ' -f2 "$tmp/time.txt") / 1024))" >>"$out"
done
tail -3 "$out"
