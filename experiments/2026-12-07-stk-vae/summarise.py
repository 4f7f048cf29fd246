"""results.csv: table 5 RMSE x100 of this experiment's VAE (`vae-srras`) and of the shipped VAE per evaluation set,
and the difference of vae-srras to each VAE of ../2026-12-06-corpus-arms on the same windows (the held-out store
and procedural validation are rebuilt identically; the real validation split is not: its store now holds
SuperTuxKart), with a 95 % interval from 10,000 bootstrap draws resampled BY OBJECT (all windows of a drawn object
together; an object is a clip id up to `_offset`). by-object.csv: the held-out means per object."""

import csv
import pathlib

import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
ARMS = HERE.parent / "2026-12-06-corpus-arms" / "table5"
SETS = ["heldout", "real-val", "procedural-val"]
COMPARABLE = {"heldout", "procedural-val"}


def load(path, method):
    t = pq.read_table(path).to_pydict()
    return {t["clip_id"][i]: t["rmse"][i] for i in range(len(t["method"])) if t["method"][i] == method}


def obj(clip_id):
    return clip_id.split("_offset")[0]


def paired(a, b, rng):
    ids = sorted(set(a) & set(b))
    objs = sorted({obj(i) for i in ids})
    d = {o: [a[i] - b[i] for i in ids if obj(i) == o] for o in objs}
    mean = np.mean([x for o in objs for x in d[o]])
    boots = [np.mean([x for k in rng.integers(0, len(objs), len(objs)) for x in d[objs[k]]]) for _ in range(10000)]
    return len(ids), len(objs), 100 * mean, 100 * np.percentile(boots, 2.5), 100 * np.percentile(boots, 97.5)


def main():
    rng = np.random.default_rng(0)
    rows = []
    for s in SETS:
        path = HERE / f"table5-{s}" / "clips.parquet"
        ours, shipped = load(path, "framewise_b"), load(path, "framewise")
        n, o, d, lo, hi = paired(ours, shipped, rng)
        rows.append([s, "vae-srras", "shipped", n, o, 100 * np.mean(list(ours.values())),
                     100 * np.mean(list(shipped.values())), d, lo, hi])
        if s not in COMPARABLE:
            continue
        for arm in sorted(p.name for p in ARMS.iterdir()):
            other = load(ARMS / arm / s / "clips.parquet", "framewise_b")
            n, o, d, lo, hi = paired(ours, other, rng)
            rows.append([s, "vae-srras", arm, n, o, 100 * np.mean([ours[k] for k in other]),
                         100 * np.mean(list(other.values())), d, lo, hi])
    with open(HERE / "results.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["set", "vae", "against", "windows", "objects", "rmse_x100", "against_rmse_x100",
                    "difference_x100", "ci95_low", "ci95_high"])
        w.writerows([r[:5] + [f"{x:.3f}" for x in r[5:]] for r in rows])
    held = HERE / "table5-heldout" / "clips.parquet"
    ours, shipped = load(held, "framewise_b"), load(held, "framewise")
    srra = load(ARMS / "vae-srra" / "heldout" / "clips.parquet", "framewise_b")
    with open(HERE / "by-object.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["object", "windows", "vae_srras", "vae_srra", "shipped"])
        for o in sorted({obj(i) for i in ours}):
            ks = [k for k in ours if obj(k) == o]
            w.writerow([o, len(ks)] + [f"{100 * np.mean([m[k] for k in ks]):.2f}" for m in (ours, srra, shipped)])
    for r in rows:
        print(*r[:5], *(f"{x:.2f}" for x in r[5:]))


if __name__ == "__main__":
    main()
