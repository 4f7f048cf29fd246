"""Table 5 of the motion-augmented arm (vae-motion15) against the shipped VAE and, window by window, against the
vae-repro separating arm it differs from by `vae.augment.motion` alone (same windows: same names, the shipped VAE
scoring each alike to 1e-3), with 95 % intervals of the mean difference resampled by object: results.csv,
by-object.csv (held out), from table5/<set>/clips.parquet and ../2026-12-07-vae-repro/table5/; and, when
latent_lerp.sh has run, latent_lerp.csv: per VAE and K_x the held-out RMSE ×100 of lerp, lerp_latent and
vae_oracle and the ratio lerp_latent / lerp of the means, with a 95 % interval resampled by object. numpy,
pyarrow."""

import csv
import pathlib

import numpy as np
import pyarrow.parquet as pq

HERE = pathlib.Path(__file__).resolve().parent
BASE = HERE.parent / "2026-12-07-vae-repro" / "table5" / "vae-srra-nostk-rig5"
SETS = ["heldout", "procedural-val"]


def object_uid(clip_id):
    return clip_id.split("_offset")[0]


def load(folder):
    """{(item, clip id): RMSE ×100} of the shipped VAE and of the other VAE in `folder`."""
    t = pq.read_table(folder / "clips.parquet").to_pydict()
    by = {}
    for m, item, cid, rmse in zip(t["method"], t["item"], t["clip_id"], t["rmse"]):
        by.setdefault(m, {})[(item, cid)] = rmse * 100
    return by["framewise"], by["framewise_b"]


def interval(diff, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    sums = np.array([diff[g].sum() for g in groups])
    counts = np.array([len(g) for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    return np.percentile(sums[draws].sum(axis=1) / counts[draws].sum(axis=1), [2.5, 97.5])


def write(path, table):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)


def main():
    rows, by_object = [], []
    for name in SETS:
        shipped, ours = load(HERE / "table5" / name)
        shipped_then, base = load(BASE / name)
        keys = sorted(ours)
        if sorted(base) != keys:
            raise SystemExit(f"{name}: the windows differ from the separating arm's")
        drift = max(abs(shipped[k] - shipped_then[k]) for k in keys)
        if drift > 1e-3:
            raise SystemExit(f"{name}: the shipped VAE scores the windows differently ({drift}): not the same windows")
        objects = np.array([object_uid(c) for _, c in keys])
        o = np.array([ours[k] for k in keys])
        b = np.array([base[k] for k in keys])
        lo, hi = interval(o - b, objects)
        rows.append({
            "set": name, "windows": len(keys), "objects": len(np.unique(objects)),
            "shipped": f"{np.mean([shipped[k] for k in keys]):.3f}", "separating_arm": f"{b.mean():.3f}",
            "motion_aug": f"{o.mean():.3f}", "diff": f"{(o - b).mean():+.3f}", "ci_low": f"{lo:+.3f}",
            "ci_high": f"{hi:+.3f}",
        })
        if name == "heldout":
            for u in np.unique(objects):
                m = objects == u
                by_object.append({"object": u, "windows": int(m.sum()), "separating_arm": f"{b[m].mean():.3f}",
                                  "motion_aug": f"{o[m].mean():.3f}"})
    write(HERE / "results.csv", rows)
    write(HERE / "by-object.csv", by_object)
    for r in rows:
        print(r)
    latent_lerp()


def ratio_interval(num, den, objects, reps=10000, seed=0):
    rng = np.random.default_rng(seed)
    uniq = np.unique(objects)
    groups = [np.flatnonzero(objects == u) for u in uniq]
    n = np.array([num[g].sum() for g in groups])
    d = np.array([den[g].sum() for g in groups])
    draws = rng.integers(0, len(uniq), size=(reps, len(uniq)))
    return np.percentile(n[draws].sum(axis=1) / d[draws].sum(axis=1), [2.5, 97.5])


def latent_lerp():
    rows = []
    for vae in ["separating-arm", "motion15"]:
        path = HERE / "table1" / vae / "clips.parquet"
        if not path.exists():
            continue
        t = pq.read_table(path).to_pydict()
        by = {}
        for m, k, item, cid, rmse in zip(t["method"], t["k_extra"], t["item"], t["clip_id"], t["rmse"]):
            by.setdefault((m, k), {})[(item, cid)] = rmse * 100
        for k in sorted({k for _, k in by}):
            keys = sorted(by[("lerp", k)])
            objects = np.array([object_uid(c) for _, c in keys])
            col = {m: np.array([by[(m, k)][key] for key in keys]) for m in ["lerp", "lerp_latent", "vae_oracle"]}
            lo, hi = ratio_interval(col["lerp_latent"], col["lerp"], objects)
            rows.append({
                "vae": vae, "k_x": k, "windows": len(keys), "lerp": f"{col['lerp'].mean():.3f}",
                "lerp_latent": f"{col['lerp_latent'].mean():.3f}", "vae_oracle": f"{col['vae_oracle'].mean():.3f}",
                "latent_over_lerp": f"{col['lerp_latent'].mean() / col['lerp'].mean():.3f}",
                "ci_low": f"{lo:.3f}", "ci_high": f"{hi:.3f}",
            })
    if rows:
        write(HERE / "latent_lerp.csv", rows)
        for r in rows:
            print(r)


if __name__ == "__main__":
    main()
