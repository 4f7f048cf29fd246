#!/usr/bin/env bash
# Record of the second call on the GPU machine: the build with burn's kernel fusion (packed as in device-run1.sh).
set -u
OUT=$1
R=$PWD
t0=$(date +%s)
el() { echo $(( $(date +%s) - t0 )); }
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f $icd ] && export VK_DRIVER_FILES=$icd __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
xz -dc .gpubin/any4d.xz > /tmp/any4d && chmod +x /tmp/any4d
B=/tmp/any4d
{ date; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader; $B --version; } > $OUT/env.txt 2>&1
mkdir -p /tmp/r2 && cd /tmp/r2
S=(bench sample --rf-config $R/configs/rf/paper.toml --vae-config $R/configs/vae/paper.toml --backend vulkan --vertices 4096 --frames 16 --n-grid 64)
T=(bench train --config $R/configs/rf/paper.toml --backends vulkan --steps 20)
step() { # name cap command...
    local name=$1 cap=$2; shift 2
    local s=$(date +%s%N)
    echo "== $name: $*" > /tmp/r2/$name.log
    timeout $cap "$@" >> /tmp/r2/$name.log 2>&1
    echo "$name rc $? wall $(( ($(date +%s%N) - s) / 1000000 )) ms at $(el) s" >> $OUT/env.txt
}
step table4_f32 45 $B "${S[@]}" --precision f32 --reps 2 --out /tmp/r2/t4f32
step table4_f16 35 $B "${S[@]}" --precision f16 --reps 2 --out /tmp/r2/t4f16
step train_f32 40 $B "${T[@]}" --precision f32 --peak-tflops 66.9
step train_f16 35 $B "${T[@]}" --precision f16 --peak-tflops 989
step train_bf16 35 $B "${T[@]}" --precision bf16 --peak-tflops 989
printf '[profiling.logger]\nlevel = "basic"\nfile = "/tmp/r2/prof_f16.log"\nappend = false\n' > cubecl.toml
step prof_sample_f16 30 $B bench sample --rf-config $R/configs/rf/paper.toml --vae-config $R/configs/vae/paper.toml --backend vulkan --vertices 4096 --frames 16 --n-grid 8 --precision f16 --reps 1 --out /tmp/r2/p16
rm -f cubecl.toml
python3 $R/.gpubin/prof_summary.py /tmp/r2/prof_f16.log > $OUT/profile2.csv 2>>$OUT/env.txt
gzip -c /tmp/r2/prof_f16.log > $OUT/prof_f16.log.gz
cd /tmp/r2 && cat table4_f32.log table4_f16.log train_f32.log train_f16.log train_bf16.log prof_sample_f16.log > $OUT/logs.txt
cat $OUT/env.txt; grep -hE "^\| keyframe|^vulkan|error" $OUT/logs.txt; head -25 $OUT/profile2.csv | cut -c1-200
