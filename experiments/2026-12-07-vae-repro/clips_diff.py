"""How far today's procedural and rigged clips are from the a5fd204 generator's (the clips the corpus-arms VAEs were
trained on): per clip, the RMS distance between the two stores' normalised vertices (same seed, same options, same
ids), written to clips_diff.csv and summarised by family. numpy and scripts/read_any4d.py.

  python3 experiments/2026-12-07-vae-repro/clips_diff.py TODAY_STORE OLD_STORE
"""

import csv
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "scripts"))
from read_any4d import read_store  # noqa: E402


def main(today, old):
    _, _, a = read_store(today)
    _, _, b = read_store(old)
    old_by_id = {c["id"]: c for c in b}
    rows = []
    for c in a:
        o = old_by_id.get(c["id"])
        if o is None:
            continue
        same_shape = c["vertices"].shape == o["vertices"].shape
        rms = float(np.sqrt(np.mean((c["vertices"] - o["vertices"]) ** 2))) if same_shape else float("nan")
        family = "rigged" if "rigged" in c["source"] else "shapes"
        rows.append({"id": c["id"], "family": family, "vertices": c["vertices"].shape[1], "same_shape": same_shape,
                     "rms_diff": f"{rms:.3e}", "same_caption": c["caption"] == o["caption"]})
    with open(HERE / "clips_diff.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for family in ("shapes", "rigged"):
        r = [x for x in rows if x["family"] == family]
        d = np.array([float(x["rms_diff"]) for x in r])
        print(f"{family}: {len(r)} clips, {sum(not x['same_shape'] for x in r)} of other size, "
              f"{int(np.sum(d == 0))} identical, RMS difference median {np.nanmedian(d):.3e}, max {np.nanmax(d):.3e}, "
              f"{sum(not x['same_caption'] for x in r)} captions differ")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
