"""Paired comparison of two table-1 runs' per-clip parquet on the same manifest: for each K_x, the mean over
(clip, seed) of ratio = rmse_b / rmse_a and of difference, with a bootstrap 95 % interval over clips."""
import sys, numpy as np, pyarrow.parquet as pq
def load(p, method):
    t = pq.read_table(p).to_pydict()
    out = {}
    for i in range(len(t['method'])):
        if t['method'][i] == method:
            out[(t['k_extra'][i], t['seed'][i], t['item'][i])] = t['rmse'][i]
    return out
a = load(sys.argv[1], sys.argv[2]); b = load(sys.argv[3], sys.argv[4])
rng = np.random.default_rng(0)
print("k_extra,pairs,mean_a_x100,mean_b_x100,mean_diff_x100,ci_lo,ci_hi,b_wins_frac")
for k in sorted({key[0] for key in a}):
    keys = sorted(key for key in a if key[0] == k and key in b)
    items = sorted({key[2] for key in keys})
    d = {it: [b[key]-a[key] for key in keys if key[2]==it] for it in items}
    per_item = np.array([np.mean(d[it]) for it in items])
    boots = [rng.choice(per_item, len(per_item)).mean() for _ in range(4000)]
    lo, hi = np.percentile(boots, [2.5, 97.5])
    wins = np.mean([b[key] < a[key] for key in keys])
    print(f"{k},{len(keys)},{100*np.mean([a[x] for x in keys]):.2f},{100*np.mean([b[x] for x in keys]):.2f},{100*per_item.mean():.3f},{100*lo:.3f},{100*hi:.3f},{wins:.3f}")
