#!/usr/bin/env bash
# The GPU check in one call (README "Benchmarks"): on a machine with an NVIDIA GPU, times ours at the paper's size on
# a GPU backend and writes one table as CSV. Build the binary where cargo can fetch crates, then run it there:
#
#   cargo build --release --features vulkan        # or --features cuda (needs the CUDA driver and NVRTC there)
#   scripts/gpu_check.sh OUT                        # ANY4D_BIN=path/to/any4d if not target/release/any4d
#   scripts/gpu_check.sh --dry-run OUT              # the same sequence on the CPU at tiny sizes (tests use this)
#
# Steps, each under a time limit (60 s; 220 s for the Table 4 timing, which runs 24 samplings of 63 midpoint steps):
# at most 8 minutes in all on vulkan (cuda adds two bf16 steps: 8 min 40 s). Measured on H200s in
# experiments/2026-12-04-gpu-check and -gpu-half-fusion; burn's
# kernel fusion (on in GPU builds) compiles its kernels at first use: about 20 s more start-up per step in the one
# comparison made (inferred from two runs' wall times, not timed directly).
#   1. the GPU's name and memory (nvidia-smi);
#   2. `bench model --size paper`: RF forward+backward and VAE encode+decode per clip, in f32 and in the backend's
#      half precision (ANY4D_GPU_HALF: f16 on vulkan, bf16 on cuda; `none` skips it);
#   3. `bench train` of configs/rf/paper.toml: steps/s, model TFLOP/s and the fraction of the GPU's peak
#      (ANY4D_PEAK_TFLOPS, default 66.9: the H100/H200 SXM FP32 peak without tensor cores; state which peak);
#      also in bf16 when that is the half precision, against ANY4D_PEAK_HALF_TFLOPS (default 989: dense bf16 with
#      tensor cores; training in f16 is refused, see README "Training on a GPU");
#   4. `bench sample`: P-Table 4, encode → 63-step midpoint sampling → decode, 16 and 31 frames, 512–4096 vertices
#      (freshly initialised networks: the work does not depend on the weights), in ANY4D_TABLE4_PRECISION
#      (default f32, the paper's);
#   5. `bench train` of configs/rf/small.toml at its P = 128 for 150 steps: the small preset's steps/s.
# Output: OUT/gpu_check.csv (check, backend, precision, value, unit, command) and one log per step in OUT/.
# A step that fails or runs out of time gets a row with value "failed" or "timeout" and the rest still run; the
# exit status is non-zero if any step failed.
set -uo pipefail

dry=0
if [[ "${1:-}" == "--dry-run" ]]; then
    dry=1
    shift
fi
out=${1:?usage: scripts/gpu_check.sh [--dry-run] OUT}
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${ANY4D_BIN:-$root/target/release/any4d}
if [[ ! -x "$bin" ]]; then
    echo "gpu_check: no any4d binary at $bin (build it, or set ANY4D_BIN)" >&2
    exit 2
fi
mkdir -p "$out" || exit 2
csv="$out/gpu_check.csv"
echo "check,backend,precision,value,unit,command" >"$csv"

if ((dry)); then
    backend=flex
    size=tiny
    rf_paper=$root/configs/rf/tiny.toml
    vae_paper=$root/configs/vae/tiny.toml
    rf_small=$root/configs/rf/tiny.toml
    vertices=256,512
    grid=4
    reps=1
    table4_reps=1
    train_steps=3
    small_steps=3
    small_tokens=32
    limit=120
    table4_limit=120
    # The CPU backends compute in f32 only and refuse a half precision after parsing the command line, so setting
    # ANY4D_GPU_HALF here checks the half-precision steps' command lines (their rows then read "failed").
    half=${ANY4D_GPU_HALF:-none}
    table4_precision=f32
else
    backend=${ANY4D_GPU_BACKEND:-vulkan}
    size=paper
    rf_paper=$root/configs/rf/paper.toml
    vae_paper=$root/configs/vae/paper.toml
    rf_small=$root/configs/rf/small.toml
    vertices=512,1024,2048,4096
    grid=64
    reps=3
    table4_reps=2
    train_steps=20
    small_steps=${ANY4D_SMALL_STEPS:-150}
    small_tokens=128 # configs/vae/small.toml's P
    limit=60
    table4_limit=220
    half_default=f16
    [[ "$backend" == cuda ]] && half_default=bf16
    half=${ANY4D_GPU_HALF:-$half_default}
    table4_precision=${ANY4D_TABLE4_PRECISION:-f32}
fi
peak=${ANY4D_PEAK_TFLOPS:-66.9}
peak_half=${ANY4D_PEAK_HALF_TFLOPS:-989}
status=0

row() { # check precision value unit command
    printf '%s,%s,%s,%s,%s,"%s"\n' "$1" "$backend" "$2" "$3" "$4" "$5" >>"$csv"
}

# Runs a step with a time limit; its output goes to OUT/NAME.log. Returns its exit status (124 = timeout).
run_step() { # name command...
    local name=$1
    shift
    local cap=$limit start=$SECONDS
    [[ "$name" == table4 ]] && cap=$table4_limit
    echo "== $name: $*" >&2
    timeout "$cap" "$@" >"$out/$name.log" 2>&1
    local rc=$?
    echo "   $name: $((SECONDS - start)) s (limit $cap s)" >&2
    if ((rc != 0)); then
        status=1
        echo "   $name: exit $rc (see $out/$name.log)" >&2
    fi
    return $rc
}

failed_row() { # check precision rc command
    local what=failed
    (($3 == 124)) && what=timeout
    row "$1" "$2" "$what" "" "$4"
}

# 1. The device.
if ((dry)); then
    row device "" "cpu (dry run)" "" "none"
elif command -v nvidia-smi >/dev/null; then
    gpu=$(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | head -n 1 | tr ',' ';')
    row device "" "$gpu" "name; memory; driver" "nvidia-smi"
else
    row device "" "unknown (no nvidia-smi)" "" "nvidia-smi"
fi

# 2. Networks per clip.
model_rows() { # name precision
    local name=$1 precision=$2
    local c=("$bin" bench model --size "$size" --backend "$backend" --precision "$precision" --iters "$reps")
    if run_step "$name" "${c[@]}"; then
        for net in "RF forward+backward" "frame-wise VAE encode+decode" "sequence-wise DyMeshVAE encode+decode"; do
            local ms
            ms=$(grep -F "bench model: $net" "$out/$name.log" | sed -nE 's/.* ([0-9.]+) ms\/clip$/\1/p')
            row "model: $net" "$precision" "${ms:-parse-error}" "ms/clip" "${c[*]}"
        done
    else
        failed_row "model: networks" "$precision" $? "${c[*]}"
    fi
}
model_rows bench_model f32
[[ "$half" != none ]] && model_rows "bench_model_$half" "$half"

# 3. Paper-size training step: steps/s, TFLOP/s, fraction of the peak.
train_row() { # name precision peak config steps [tokens]
    local name=$1 precision=$2 cpeak=$3 config=$4 steps=$5
    local c=("$bin" bench train --config "$config" --backends "$backend" --steps "$steps" --peak-tflops "$cpeak")
    [[ -n "${6:-}" ]] && c+=(--tokens "$6")
    c+=(--precision "$precision")
    if run_step "$name" "${c[@]}"; then
        # The result row: backend micro_batch median_s steps/s samples/s GFLOP/step GFLOP/s of_peak
        local line
        line=$(grep -E "^$backend[[:space:]]" "$out/$name.log" | tail -n 1)
        read -r _ _ _ sps _ _ gflops frac <<<"$line"
        row "$name: steps/s" "$precision" "${sps:-parse-error}" "steps/s" "${c[*]}"
        row "$name: model FLOP/s" "$precision" "${gflops:-parse-error}" "GFLOP/s" "${c[*]}"
        row "$name: fraction of peak" "$precision" "${frac:-parse-error}" "of $cpeak TFLOP/s" "${c[*]}"
    else
        failed_row "$name" "$precision" $? "${c[*]}"
    fi
}
train_row train_paper f32 "$peak" "$rf_paper" "$train_steps"
[[ "$half" == bf16 ]] && train_row "train_paper_$half" "$half" "$peak_half" "$rf_paper" "$train_steps"

# 4. P-Table 4 timing.
cmd=("$bin" bench sample --rf-config "$rf_paper" --vae-config "$vae_paper" --backend "$backend"
    --precision "$table4_precision" --vertices "$vertices" --frames 16,31 --reps "$table4_reps" --n-grid "$grid"
    --out "$out/table4")
if run_step table4 "${cmd[@]}"; then
    # summary.csv: one line per method × frames, a column v<N> per vertex count.
    python3 - "$out/table4/summary.csv" "$backend" "$table4_precision" "${cmd[*]}" >>"$csv" <<'EOF' || status=1
import csv, sys
path, backend, precision, command = sys.argv[1:]
with open(path) as f:
    rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
header, body = rows[0], rows[1:]
frames_col = header.index("frames")
printed = 0
for r in body:
    for h, v in zip(header, r):
        if h.startswith("v") and h[1:].isdigit():  # v512: seconds per clip at 512 vertices
            print(f'table4: {r[frames_col]} frames {h[1:]} vertices,{backend},{precision},{float(v):.4f},s/clip,"{command}"')
            printed += 1
sys.exit(0 if printed else f"no timing columns in {path}")
EOF
else
    failed_row "table4" "$table4_precision" $? "${cmd[*]}"
fi

# 5. The small preset's training throughput at its P (ANY4D_SMALL_STEPS steps, default 150).
train_row train_small f32 "$peak" "$rf_small" "$small_steps" "$small_tokens"

if command -v column >/dev/null; then column -s, -t <"$csv"; else cat "$csv"; fi
echo "written to $csv"
exit $status
