# Shares of a `perf record --call-graph dwarf` profile's samples whose stack passes through given functions:
#   perf script -i perf.data -F comm,tid,ip,sym > stacks.txt
#   python3 share.py stacks.txt > profile-share.csv
import csv, sys

WHERE = [  # (row, predicate on the stack: leaf first)
    ("all samples", lambda s: True),
    ("under Bytes::try_enforce_runtime_align (the realignment copy, its allocation and page faults)",
     lambda s: any("try_enforce_runtime_align" in f for f in s)),
    ("  of which the memcpy itself", lambda s: any("try_enforce_runtime_align" in f for f in s)
     and ("memcpy" in s[0] or "memmove" in s[0])),
    ("under burn-flex FlexTensor::empty (all of its allocations)", lambda s: any("FlexTensor::empty" in f for f in s)),
    ("every memcpy/memmove", lambda s: "memcpy" in s[0] or "memmove" in s[0]),
    ("gemm microkernels", lambda s: "gemm_f32::microkernel" in s[0]),
]

stacks, cur = [], []
for line in open(sys.argv[1], errors="replace"):
    if not line.strip() or line[0] not in " \t":
        if cur:
            stacks.append(cur)
        cur = []
        continue
    parts = line.split(None, 1)
    cur.append(parts[1].strip() if len(parts) > 1 else "")
if cur:
    stacks.append(cur)
out = csv.writer(sys.stdout)
out.writerow(["where", "samples", "share"])
for name, pred in WHERE:
    k = sum(1 for s in stacks if s and pred(s))
    out.writerow([name, k, f"{k / len(stacks):.4f}"])
