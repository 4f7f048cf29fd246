"""Per-step losses of each corpus-arms VAE retrained by today's code beside the committed ones (compare.csv), and
per arm the first step whose loss differs and the largest relative difference (summary.csv). Standard library only."""

import csv
import pathlib

HERE = pathlib.Path(__file__).resolve().parent
ARMS = HERE.parent / "2026-12-06-corpus-arms" / "runs"
COLUMNS = ("rec", "kl", "grad_norm")


def read(path):
    with open(path, newline="") as f:
        return {int(r["step"]): r for r in csv.DictReader(f)}


def main():
    rows, summary = [], []
    for run in sorted((HERE / "runs").glob("*/*")):
        label = run.parent.name
        then, now = read(ARMS / run.name / "metrics.csv"), read(run / "metrics.csv")
        first, worst = None, 0.0
        for step in sorted(now):
            if step not in then:
                continue
            row = {"stores": label, "arm": run.name, "step": step}
            for c in COLUMNS:
                a, b = float(then[step][c]), float(now[step][c])
                rel = abs(a - b) / max(abs(a), 1e-30)
                row[f"{c}_committed"], row[f"{c}_today"], row[f"{c}_rel_diff"] = then[step][c], now[step][c], f"{rel:.3e}"
                worst = max(worst, rel)
                if rel > 0 and first is None:
                    first = step
            rows.append(row)
        steps = len([s for s in now if s in then])
        summary.append({"stores": label, "arm": run.name, "steps_compared": steps, "first_step_differing": first or "none",
                        "max_rel_diff": f"{worst:.3e}"})
        print(f"{label} {run.name}: {steps} steps compared, first differing step {first or 'none'}, "
              f"largest relative difference {worst:.3e}")
    with open(HERE / "compare.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(HERE / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(summary[0]))
        w.writeheader()
        w.writerows(summary)


if __name__ == "__main__":
    main()
