"""Where a method loses to lerp: windows binned by how much their ground truth moves (terciles of the ground
truth's motion energy over the scored frames, the `energy_gt` column, fixed per window at K_x = 0), each row's mean
RMSE x100 per bin and K_x, and its ratio over lerp's.

usage: motion_bins.py OUT.csv LABEL=PARQUET:METHOD [LABEL=...]   (one row must be labelled `lerp`)"""

import sys

import numpy as np
import pyarrow.parquet as pq


def load(spec):
    label, rest = spec.split("=", 1)
    path, method = rest.rsplit(":", 1)
    t = pq.read_table(path).to_pydict()
    rows = {}
    for i, m in enumerate(t["method"]):
        if m == method:
            rows[(t["k_extra"][i], t["seed"][i], t["item"][i])] = (t["rmse"][i], t["energy_gt"][i])
    if not rows:
        sys.exit(f"{spec}: no rows of method {method}")
    return label, rows


def main():
    rows = dict(load(s) for s in sys.argv[2:])
    common = set.intersection(*(set(r) for r in rows.values()))
    base = {(s, i): rows["lerp"][(k, s, i)][1] for (k, s, i) in common if k == 0}
    edges = np.quantile(list(base.values()), [1 / 3, 2 / 3])
    bin_of = {w: int(np.searchsorted(edges, e, side="right")) for w, e in base.items()}
    names = ("still", "middle", "moving")
    out = ["k_extra,bin,windows,energy_gt_lo,energy_gt_hi," + ",".join(f"{l}_rmse_x100" for l in rows)
           + "," + ",".join(f"{l}_over_lerp" for l in rows if l != "lerp")]
    for k in sorted({key[0] for key in common}):
        for b in range(3):
            keys = [key for key in common if key[0] == k and bin_of.get(key[1:]) == b]
            if not keys:
                continue
            energy = [base[key[1:]] for key in keys]
            means = {l: 100 * np.mean([rows[l][key][0] for key in keys]) for l in rows}
            ratios = [means[l] / means["lerp"] for l in rows if l != "lerp"]
            out.append(f"{k},{names[b]},{len(keys)},{min(energy):.3e},{max(energy):.3e},"
                       + ",".join(f"{means[l]:.3f}" for l in rows) + "," + ",".join(f"{r:.3f}" for r in ratios))
    open(sys.argv[1], "w").write("\n".join(out) + "\n")
    print("\n".join(out))


if __name__ == "__main__":
    main()
