#!/usr/bin/env bash
# Before/after of farthest point sampling with a laned arg-max under runtime SIMD dispatch (data/src/fps.rs),
# alternating two release builds, five rounds, on the otherwise idle 2-core CPU: `any4d bench data --clips 64`
# (64 clips × 16 frames × 4096 vertices written as .bin, read, normalised and sampled to P = 512 on one thread,
# beside the numpy reference on one core, which must pick the same indices). One timing per process, so five rounds.
# BEFORE / AFTER: release builds of the commit before the change and with it. Writes runs/*.txt, rates.csv and
# summary.csv.
set -euo pipefail
before=${1:?usage: ab.sh BEFORE_BIN AFTER_BIN}; after=${2:?}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$here/runs"
echo "binary,round,ours_clips_s,reference_clips_s,ratio,indices_agree" > "$here/rates.csv"
for round in 1 2 3 4 5; do
    for v in before after; do
        bin=$before; [[ $v == after ]] && bin=$after
        "$bin" bench data --clips 64 > "$here/runs/$v-$round.txt" 2>&1
        python3 - "$here/runs/$v-$round.txt" "$v" "$round" >> "$here/rates.csv" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
ours = re.search(r"ours \(1 thread\):\s+([0-9.]+) clips/s", text).group(1)
ref = re.search(r"numpy reference \(1 core\):\s+([0-9.]+) clips/s", text).group(1)
ratio = re.search(r"ratio ours / reference: ([0-9.]+)×", text).group(1)
agree = re.search(r"FPS indices agree \(checksum [0-9]+\): (\w+)", text).group(1)
print(",".join([sys.argv[2], sys.argv[3], ours, ref, ratio, agree]))
PY
    done
done
python3 - "$here/rates.csv" "$here/summary.csv" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
cols = ["ours_clips_s", "reference_clips_s", "ratio"]
with open(sys.argv[2], "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["binary"] + [f"{c}_median" for c in cols] + [f"{c}_min" for c in cols] + [f"{c}_max" for c in cols]
               + ["indices_agree_in_every_run"])
    for v in ("before", "after"):
        vals = {c: [float(r[c]) for r in rows if r["binary"] == v] for c in cols}
        agree = all(r["indices_agree"] == "yes" for r in rows if r["binary"] == v)
        w.writerow([v] + [f"{statistics.median(vals[c]):.2f}" for c in cols] + [f"{min(vals[c]):.2f}" for c in cols]
                   + [f"{max(vals[c]):.2f}" for c in cols] + ["yes" if agree else "no"])
PY
cat "$here/summary.csv"
