#!/usr/bin/env bash
# Record of the first call on the GPU machine (device side; the build machine packed the binary as .gpubin/any4d.xz and
# the Vulkan loader packages as .gl/*.deb, both carried beside the working tree).
set -u
OUT=$1
R=$PWD
t0=$(date +%s)
el() { echo $(( $(date +%s) - t0 )); }
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f $icd ] && export VK_DRIVER_FILES=$icd __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
(xz -dc .gpubin/any4d.xz || python3 -c 'import lzma,sys;sys.stdout.buffer.write(lzma.open(".gpubin/any4d.xz").read())') > /tmp/any4d && chmod +x /tmp/any4d
B=/tmp/any4d
{ date; nvidia-smi; echo "VK=${VK_DRIVER_FILES:-}"; nproc; $B --version; } > $OUT/env.txt 2>&1
echo "setup $(el) s" >> $OUT/env.txt
mkdir -p /tmp/prof && cd /tmp/prof
S=(bench sample --rf-config $R/configs/rf/paper.toml --vae-config $R/configs/vae/paper.toml --backend vulkan --vertices 4096)
prof() { # name cap command...
    local name=$1 cap=$2; shift 2
    printf '[profiling.logger]\nlevel = "basic"\nfile = "/tmp/prof/%s.log"\nappend = false\n' "$name" > cubecl.toml
    local s=$(date +%s%N)
    timeout $cap "$@" > /tmp/prof/$name.out 2>&1
    echo "$name rc $? wall $(( ($(date +%s%N) - s) / 1000000 )) ms at $(el) s" >> $OUT/env.txt
}
prof sample_f32 35 $B "${S[@]}" --precision f32 --frames 16 --reps 1 --n-grid 8 --out /tmp/prof/s32
prof sample_f16 35 $B "${S[@]}" --precision f16 --frames 16 --reps 1 --n-grid 8 --out /tmp/prof/s16
prof train_f16 35 $B bench train --config $R/configs/rf/paper.toml --backends vulkan --precision f16 --steps 3 --peak-tflops 989
rm -f cubecl.toml
s=$(date +%s%N); timeout 45 $B "${S[@]}" --precision f16 --frames 16,31 --reps 2 --n-grid 64 --out /tmp/prof/t4f16 > /tmp/prof/t4f16.out 2>&1
echo "table4 f16 rc $? wall $(( ($(date +%s%N) - s) / 1000000 )) ms at $(el) s" >> $OUT/env.txt
python3 $R/.gpubin/prof_summary.py /tmp/prof/*.log > $OUT/profile.csv 2>>$OUT/env.txt
cd $R
ANY4D_BIN=$B timeout 385 scripts/gpu_check.sh /tmp/gc > /tmp/gc.out 2>&1; echo "gpu_check rc $? at $(el) s" >> $OUT/env.txt
cp /tmp/gc/gpu_check.csv $OUT/gpu_check.csv
tar czf $OUT/logs.tar.gz -C /tmp gc gc.out prof
ls -la $OUT >> $OUT/env.txt
cat $OUT/env.txt | tail -n 25; cat /tmp/prof/t4f16.out | tail -n 12; head -c 3000 $OUT/profile.csv; column -s, -t < $OUT/gpu_check.csv | cut -c1-120
