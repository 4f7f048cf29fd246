"""Reads the logs of ab.sh and ab-trained.sh into steps.csv (one row per what, binary and round, with its time) and
summary.csv (the medians and their ratio).

    python3 summarise.py            (from this folder)
"""
import csv
import glob
import os
import re
import statistics

HERE = os.path.dirname(os.path.abspath(__file__))
LOGS = os.path.join(HERE, "logs")
rows = []

# bench train (fresh weights): the median step time of the flex row.
for path in sorted(glob.glob(os.path.join(LOGS, "rf-train-*.txt"))):
    _, _, binary, rnd = os.path.basename(path)[:-4].split("-")
    flex = [l.split() for l in open(path) if l.startswith("flex")][0]
    rows.append(("rf_train_step_fresh", binary, rnd, float(flex[2]), "s per step (bench train, 16 clips, one device)"))
for path in sorted(glob.glob(os.path.join(LOGS, "vae-train-*.txt"))):
    _, _, binary, rnd = os.path.basename(path)[:-4].split("-")
    flex = [l.split() for l in open(path) if l.startswith("flex")][0]
    rows.append(("vae_train_step_fresh", binary, rnd, 1.0 / float(flex[2]), "s per step (bench train, median)"))
# bench sample (fresh weights): encode -> 16-point sampling -> decode of one clip.
for path in sorted(glob.glob(os.path.join(LOGS, "sample-*.txt"))):
    _, binary, rnd = os.path.basename(path)[:-4].split("-")
    line = [l for l in open(path) if l.startswith("| keyframe_rf | 16 |")][0]
    rows.append(("sample_fresh", binary, rnd, float(line.split("|")[3]), "s per clip (bench sample, median of 3)"))
# eval with the shipped RF (trained weights), end to end.
for what, binary, rnd, secs in csv.reader(open(os.path.join(LOGS, "eval-times.csv"))):
    rows.append(("eval_trained", binary, rnd, float(secs), "s per eval run (12 clips x 4 K_x, shipped RF)"))
# the real training loop resumed at step 4,000: the median over each round's metrics.csv rows of 1/steps_per_s,
# its first five rows dropped (warm-up); a round's last step is the one its log says it was interrupted after.
for binary in ("before", "after"):
    kept = os.path.join(HERE, f"metrics-{binary}.csv")
    run_metrics = os.path.join(HERE, "runs", f"rf-{binary}", "metrics.csv")
    if os.path.exists(run_metrics):
        # metrics.csv is append-only: the copied run's own rows (to step 4,500) come first, then the resumed
        # rows, which start where the step number falls back to 4,001; those are kept beside this script.
        lines = open(run_metrics).read().splitlines()
        steps = [int(l.split(",")[0]) for l in lines[1:]]
        resumed_at = next(i for i in range(1, len(steps)) if steps[i] < steps[i - 1]) + 1
        open(kept, "w").write("\n".join([lines[0]] + lines[resumed_at:]) + "\n")
    metrics = list(csv.DictReader(open(kept)))
    first = 4001
    for rnd in (1, 2):
        log = open(os.path.join(LOGS, f"train-{binary}-{rnd}.txt")).read()
        last = int(re.search(r"(?:interrupted after step|finished) (\d+)", log).group(1))
        chunk = [r for r in metrics if first <= int(r["step"]) <= last][5:]
        secs = statistics.median(1.0 / float(r["steps_per_s"]) for r in chunk)
        rows.append(("rf_train_step_trained", binary, str(rnd), secs, f"s per step (train rf resumed, {len(chunk)} steps)"))
        first = last + 1

with open(os.path.join(HERE, "steps.csv"), "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["what", "binary", "round", "seconds", "unit"])
    for r in rows:
        w.writerow([r[0], r[1], r[2], f"{r[3]:.4f}", r[4]])

print(f"{'what':24} {'before':>9} {'after':>9} {'before/after':>13}")
with open(os.path.join(HERE, "summary.csv"), "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["what", "rounds", "before_median_s", "after_median_s", "speedup"])
    for what in dict.fromkeys(r[0] for r in rows):
        b = statistics.median(r[3] for r in rows if r[0] == what and r[1] == "before")
        a = statistics.median(r[3] for r in rows if r[0] == what and r[1] == "after")
        n = sum(1 for r in rows if r[0] == what and r[1] == "after")
        w.writerow([what, n, f"{b:.4f}", f"{a:.4f}", f"{b / a:.3f}"])
        print(f"{what:24} {b:9.4f} {a:9.4f} {b / a:13.3f}")
