#!/usr/bin/env python3
"""summary.csv from logs/ (the alternating rounds against PyTorch), share-t{1,2}.csv (the profiles) and ceiling.csv.

Per network and thread count: ours' and PyTorch's median times over the rounds, the median and range of the per-round
ratios. For the RF also: the analytic FLOPs of one forward + backward (3 × the forward, `MmditConfig::forward_flops`,
docs/method.md §4.3 sizes), ours' matrix-product core-seconds per step (the profile's gemm samples ÷ 199 Hz ÷ steps),
the rate that makes, the CPU's product rate as PyTorch reaches it on the RF's shapes (`ceiling.csv`, the mean over
the four RF shapes), and the time those FLOPs take at that rate as a fraction of PyTorch's step: a lower bound for
ours/PyTorch of any step whose products run at that rate.

`bench_rows` (one `bench model --torch-reference` log's table) and `NETS` are shared with ab_summarise.py and plot.py.
"""
import csv
import glob
import os
import re
import statistics

here = os.path.dirname(os.path.abspath(__file__))
HZ = 199
NETS = [("RF forward+backward", "RF forward+backward"),
        ("frame-wise VAE encode+decode", "frame-wise VAE encode+decode"),
        ("sequence-wise DyMeshVAE enc+dec", "sequence-wise DyMeshVAE encode+decode")]


def rf_flops():
    p, l, w, blocks, d_in, d_out, d_txt, freqs = 512, 77, 512, 12, 221, 192, 768, 256
    s = p + l
    projections = p * d_in * w + l * d_txt * w + p * w * d_out
    time = 2 * freqs * 4 * w + 4 * w * w
    per_block = 2 * w * 6 * w + s * (3 * w * w + w * w + 4 * w * w + 4 * w * w)
    linear = 2 * (projections + time + blocks * per_block)
    attention = blocks * 2 * 2 * s * s * w
    return 3 * (linear + attention)


def bench_rows(path):
    """{network as the log names it: (ours ms, PyTorch ms, ours/PyTorch)} from the table a log ends with."""
    rows = {}
    for line in open(path):
        for log_name, _ in NETS:
            if line.startswith(log_name):
                ours, torch, ratio = (float(x) for x in line[len(log_name):].split()[:3])
                rows[log_name] = (ours, torch, ratio)
    return rows


def main():
    rounds = {}  # (threads, net) -> [(ours, torch, ratio)]
    for path in sorted(glob.glob(f"{here}/logs/vs-torch-t*-r*.txt")):
        threads = int(re.search(r"-t(\d)-", path).group(1))
        for log_name, row in bench_rows(path).items():
            rounds.setdefault((threads, log_name), []).append(row)

    share = {}
    for threads in (1, 2):
        with open(f"{here}/share-t{threads}.csv") as f:
            for r in csv.DictReader(f):
                share[(threads, r["network"], r["category"])] = int(r["samples"])
    steps = {t: int(re.search(r"(\d+) iters", open(f"{here}/logs/profiled-t{t}.txt").read()).group(1)) for t in (1, 2)}
    ceiling = {}
    with open(f"{here}/ceiling.csv") as f:
        for r in csv.DictReader(f):
            if int(r["m"]) == 589:
                ceiling.setdefault(int(r["threads"]), []).append(float(r["gflops"]))

    with open(f"{here}/summary.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["network", "threads", "rounds", "ours_ms", "pytorch_ms", "ratio_median", "ratio_min", "ratio_max",
                    "profile_gemm_share", "profile_cores_busy", "flops_g", "ours_gemm_core_s", "ours_gemm_gflops",
                    "ceiling_gflops", "flops_at_ceiling_over_pytorch_step"])
        for threads in (1, 2):
            for log_name, prof_name in NETS:
                rs = rounds[(threads, log_name)]
                ours = statistics.median(r[0] for r in rs)
                torch = statistics.median(r[1] for r in rs)
                ratios = [r[2] for r in rs]
                total = share[(threads, prof_name, "all timed samples")]
                gemm = share[(threads, prof_name, "gemm microkernel")] + share[(threads, prof_name, "gemm packing and dispatch")]
                busy = total / HZ / steps[threads] / (ours / 1e3)
                row = [log_name, threads, len(rs), f"{ours:.1f}", f"{torch:.1f}", f"{statistics.median(ratios):.2f}",
                       f"{min(ratios):.2f}", f"{max(ratios):.2f}", f"{gemm / total:.3f}", f"{busy:.2f}"]
                if log_name.startswith("RF"):
                    flops = rf_flops() / 1e9
                    gemm_s = gemm / HZ / steps[threads]
                    ceil = statistics.mean(ceiling[threads])
                    row += [f"{flops:.1f}", f"{gemm_s:.3f}", f"{flops / gemm_s:.1f}", f"{ceil:.1f}",
                            f"{flops / ceil / (torch / 1e3):.2f}"]
                else:
                    row += [""] * 5
                w.writerow(row)
    print(open(f"{here}/summary.csv").read())


if __name__ == "__main__":
    main()
