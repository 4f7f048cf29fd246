# Sums cubecl's per-kernel profile lines "| <duration> | <name>" (device-run*.sh run it on the GPU machine).
import csv, re, sys
from collections import defaultdict
UNIT = {"ns": 1e-9, "µs": 1e-6, "us": 1e-6, "ms": 1e-3, "s": 1.0}
out = csv.writer(sys.stdout)
out.writerow(["profile", "kernel", "count", "total_ms", "share", "mean_us"])
for path in sys.argv[1:]:
    tot = defaultdict(float); cnt = defaultdict(int)
    try:
        lines = open(path, errors="replace").read().splitlines()
    except OSError as e:
        out.writerow([path, f"unreadable: {e}", 0, 0, 0, 0]); continue
    for line in lines:
        m = re.match(r"^\|\s*([0-9.]+)(ns|µs|us|ms|s)\s*\|\s*(.*)$", line)
        if not m:
            continue
        name = re.sub(r"\s+", " ", m.group(3))[:160]
        tot[name] += float(m.group(1)) * UNIT[m.group(2)]; cnt[name] += 1
    all_s = sum(tot.values())
    name = path.rsplit("/", 1)[-1]
    out.writerow([name, "ALL", sum(cnt.values()), f"{all_s*1e3:.3f}", "1.0", ""])
    for k, v in sorted(tot.items(), key=lambda kv: -kv[1])[:40]:
        out.writerow([name, k, cnt[k], f"{v*1e3:.3f}", f"{v/all_s:.4f}", f"{v/cnt[k]*1e6:.1f}"])
