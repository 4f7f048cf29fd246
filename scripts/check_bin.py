#!/usr/bin/env python3
"""Load a DyMesh .bin written by any4d with real pickle + numpy and print what it holds (docs/method.md §2.1).

Usage: python3 scripts/check_bin.py PATH
Prints one line per key, e.g. `vertices ndarray float32 (2, 3, 3) C`, then `ok`. Exits 1 if PATH is not a dict
with a float (T, N, 3) `vertices` array, an integer (M, 3) `faces` array and a str `caption`.
Only load files you trust: pickle.load executes code in hostile files (any4d's own reader does not).
"""

import pickle
import sys

import numpy as np


def main(path):
    with open(path, "rb") as f:
        d = pickle.load(f)
    if not isinstance(d, dict):
        sys.exit(f"{path}: top-level {type(d).__name__}, expected dict")
    for k, v in d.items():
        if isinstance(v, np.ndarray):
            order = "C" if v.flags.c_contiguous else "F"
            print(f"{k} ndarray {v.dtype} {v.shape} {order}")
        else:
            print(f"{k} {type(v).__name__} {v!r}")
    v, fa, cap = d.get("vertices"), d.get("faces"), d.get("caption")
    ok = (isinstance(v, np.ndarray) and v.ndim == 3 and v.shape[2] == 3 and v.dtype.kind == "f"
          and isinstance(fa, np.ndarray) and fa.ndim == 2 and fa.shape[1] == 3 and fa.dtype.kind in "iu"
          and isinstance(cap, str))
    if not ok:
        sys.exit(f"{path}: not a DyMesh clip dict")
    print(f"vertices[0,0] {v[0, 0].tolist()} faces[0] {fa[0].tolist()}")
    print("ok")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
