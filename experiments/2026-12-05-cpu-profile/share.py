#!/usr/bin/env python3
"""Where the paper-size networks' timed steps spend their samples, per network.

    perf script -i perf.data -F time,ip,sym > stacks.txt
    python3 share.py stacks.txt BENCH_LOG > share.csv

The profiled run is `any4d bench model --size paper --iters STEPS` (its output is BENCH_LOG): each network builds,
runs one warm-up step, then STEPS timed steps, RF first, then the frame-wise VAE, then the DyMeshVAE. A network's
phase runs from the first sample whose stack names its bench function (`time_rf_step`, `time_vae_reconstruct`,
`time_dymesh_reconstruct`; perf's 16 KiB stack copy cuts many deep stacks, so not every sample names it) to the next
phase's first sample (the last one: the profile's end). Its timed steps are taken as the phase's last
STEPS × (the median step time the log reports) seconds. Each sample goes to the first category whose test its leaf
function (or, for the realignment copy, its stack) passes.
"""
import csv
import re
import sys

PHASES = [("RF forward+backward", "time_rf_step"), ("frame-wise VAE encode+decode", "time_vae_reconstruct"),
          ("sequence-wise DyMeshVAE encode+decode", "time_dymesh_reconstruct")]

CATEGORIES = [  # (name, test on (leaf, stack))
    ("gemm microkernel", lambda leaf, s: "gemm_f32::microkernel" in leaf),
    ("gemm packing and dispatch", lambda leaf, s: leaf.startswith("gemm")),
    ("burn-flex realignment copy (Bytes::try_enforce_runtime_align, its copy and page faults)",
     lambda leaf, s: any("try_enforce_runtime_align" in f for f in s)),
    ("page faults (kernel: fresh pages zeroed)", lambda leaf, s: leaf in ("clear_page_erms",) or "page_fault" in leaf
     or "handle_mm_fault" in leaf),
    ("memcpy / memmove / memset", lambda leaf, s: "memmove" in leaf or "memcpy" in leaf or "memset" in leaf),
    ("any4d host GELU (docs/method.md §11)", lambda leaf, s: any("any4d_model::gelu" in f for f in s)),
    ("libm exp (burn-flex's softmax: one scalar expf per element)", lambda leaf, s: "expf" in leaf),
    ("burn-flex element-wise kernels", lambda leaf, s: any(k in leaf for k in (
        "unary_op", "zip_map", "zip_apply", "scalar_op", "binary", "macerator", "pulp::", "reduce", "sum"))),
    ("burn-flex transposes and copies (copy_2d_tiled, gathers)", lambda leaf, s: any(k in leaf for k in (
        "copy_2d", "gather", "select", "slice", "strided", "contiguous", "permute"))),
    ("burn-flex attention", lambda leaf, s: "attention" in leaf),
    ("allocator (malloc / free)", lambda leaf, s: any(k in leaf for k in ("malloc", "free", "memalign", "_int_",
                                                                              "rdl_", "mmap", "munmap"))),
    ("other", lambda leaf, s: True),
]


ALSO = [  # (name, test on the stack), not exclusive: rows after the categories
    ("(also) the RF's forward attention, any leaf (stack through MmditBlock::joint_attention)",
     lambda s: any("joint_attention" in f for f in s)),
    ("(also) burn's unfused attention under autodiff, any leaf (stack through attention_fallback)",
     lambda s: any("attention_fallback" in f for f in s)),
    ("(also) libm expf under burn-flex's float_exp", lambda s: "expf" in s[0] and any("float_exp" in f for f in s)),
    ("(also) libm expf with attention_fallback in its (possibly cut) stack",
     lambda s: "expf" in s[0] and any("attention_fallback" in f for f in s)),
]


def records(path):
    cur = None
    for line in open(path, errors="replace"):
        if not line.strip():
            if cur:
                yield cur
            cur = None
            continue
        if line[0] not in " \t":
            cur = (float(line.split()[-1].rstrip(":")), [])
        elif cur is not None:
            parts = line.split(None, 1)
            cur[1].append(parts[1].strip() if len(parts) > 1 else "")
    if cur:
        yield cur


def categorise(stacks):
    """{category: samples}: each stack counted in the first category whose test its leaf (or stack) passes."""
    counts = {c: 0 for c, _ in CATEGORIES}
    for s in stacks:
        leaf = s[0] if s else ""
        for c, test in CATEGORIES:
            if test(leaf, s):
                counts[c] += 1
                break
    return counts


def main():
    recs = list(records(sys.argv[1]))
    log = open(sys.argv[2]).read()
    steps = int(re.search(r"(\d+) iters", log).group(1))
    medians = [float(m) / 1000 for m in re.findall(r"median ([0-9.]+) ms/step", log)]
    bounds = []
    for _, fn in PHASES:
        ts = [t for t, s in recs if any(fn in f for f in s)]
        bounds.append((min(ts), max(ts)))
    out = csv.writer(sys.stdout)
    out.writerow(["network", "category", "samples", "share"])
    for i, (name, _) in enumerate(PHASES):
        start = bounds[i][0]
        end = bounds[i + 1][0] if i + 1 < len(PHASES) else recs[-1][0]
        timed_from = end - steps * medians[i]
        timed = [s for t, s in recs if max(start, timed_from) <= t < end]
        counts = categorise(timed)
        out.writerow([name, "all timed samples", len(timed), "1.0000"])
        for c, _ in CATEGORIES:
            out.writerow([name, c, counts[c], f"{counts[c] / max(len(timed), 1):.4f}"])
        for c, test in ALSO:
            k = sum(1 for s in timed if test(s))
            out.writerow([name, c, k, f"{k / max(len(timed), 1):.4f}"])


if __name__ == "__main__":
    main()
