#!/usr/bin/env python3
"""The CPU's f32 matrix-product rate as PyTorch (MKL) reaches it, at 1 and 2 threads: the ceiling of any step made
mostly of products. One process per thread count (thread pools are sized when torch loads).

    python3 ceiling.py > ceiling.csv

Shapes (M × K × N): a square 2048 product, and the paper RF's four linear layers per token stream (589 tokens, width
512: qkv 512 → 1536, out 512 → 512, MLP 512 → 2048 and 2048 → 512). Median of 7 timed products after 2 warm-ups.
"""
import subprocess
import sys

SHAPES = [(2048, 2048, 2048), (589, 512, 1536), (589, 512, 512), (589, 512, 2048), (589, 2048, 512)]
CHILD = """
import os, sys, time
threads = int(sys.argv[1])
for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[v] = str(threads)
import torch
torch.set_num_threads(threads)
for m, k, n in %r:
    a, b = torch.randn(m, k), torch.randn(k, n)
    for _ in range(2):
        a @ b
    ts = []
    for _ in range(7):
        t = time.perf_counter(); a @ b; ts.append(time.perf_counter() - t)
    t = sorted(ts)[3]
    print(f"{threads},{m},{k},{n},{t * 1e3:.3f},{2 * m * k * n / t / 1e9:.1f}")
""" % (SHAPES,)

print("threads,m,k,n,median_ms,gflops")
for threads in (1, 2):
    out = subprocess.run([sys.executable, "-c", CHILD, str(threads)], capture_output=True, text=True, check=True)
    sys.stdout.write(out.stdout)
