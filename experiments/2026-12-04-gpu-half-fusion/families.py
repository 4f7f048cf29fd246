# Groups cubecl's per-kernel profile lines ("| <duration> | <name>") into kernel families, one CSV row per family:
#   python3 families.py profiles/*.log.gz > profile-families.csv
import csv, gzip, re, sys
from collections import defaultdict

UNIT = {"ns": 1e-9, "µs": 1e-6, "us": 1e-6, "ms": 1e-3, "s": 1.0}
FAMILIES = [  # name prefix → family (first match)
    ("Matmul", "matmul"), ("Reduce", "reduction"), ("ElemwiseFuse", "fused element-wise"),
    ("KernelBinop", "element-wise"), ("KernelScalar", "element-wise"), ("UnaryFloat", "element-wise"),
    ("MaskFill", "element-wise"), ("Cast", "cast"), ("SelectAssign", "select-assign (scatter)"),
    ("Copy", "copy"), ("SliceAssign", "slice"), ("Slice", "slice"), ("Prng", "random"), ("Full", "fill"),
]

def family(name):
    return next((f for prefix, f in FAMILIES if name.startswith(prefix)), "other")

out = csv.writer(sys.stdout)
out.writerow(["profile", "family", "kernels", "total_ms", "share", "mean_us"])
for path in sys.argv[1:]:
    opener = gzip.open if path.endswith(".gz") else open
    total, count = defaultdict(float), defaultdict(int)
    with opener(path, "rt", errors="replace") as f:
        for line in f:
            m = re.match(r"^\|\s*([0-9.]+)(ns|µs|us|ms|s)\s*\|\s*(.*)$", line)
            if m:
                fam = family(m.group(3))
                total[fam] += float(m.group(1)) * UNIT[m.group(2)]
                count[fam] += 1
    name = path.rsplit("/", 1)[-1].removesuffix(".gz").removesuffix(".log")
    all_s = sum(total.values())
    out.writerow([name, "all", sum(count.values()), f"{all_s * 1e3:.1f}", "1.000", ""])
    for fam, s in sorted(total.items(), key=lambda kv: -kv[1]):
        out.writerow([name, fam, count[fam], f"{s * 1e3:.1f}", f"{s / all_s:.3f}", f"{s / count[fam] * 1e6:.1f}"])
