"""Sampler settings of the shipped RF against its default (noise scale 1, guidance 1) and lerp, on the same windows.
Usage: sweep.py REFERENCE_PARQUET LABEL=DIR ... [--plot PNG] > sweep.csv
REFERENCE_PARQUET holds keyframe_rf (the default sampler) and lerp for the same manifest; each DIR holds a table-1
run of keyframe_rf with one changed setting. Only the (K_x, seed, item) windows every run has are compared. Columns:
means over those windows; rmse_over_* = ratio of the mean RMSEs; diff_vs_default = mean paired RMSE difference
against the default sampler with a 95 % bootstrap interval over clips (diff_ci_lo, diff_ci_hi)."""
import sys, numpy as np, pyarrow.parquet as pq

def load(path):
    t = pq.read_table(path).to_pydict()
    rows = {}
    for i in range(len(t['method'])):
        key = (t['method'][i], t['k_extra'][i], t['seed'][i], t['item'][i])
        rows[key] = {m: t[m][i] for m in ('rmse', 'chamfer', 'dtw', 'jerk_ratio')}
    return rows

args = sys.argv[1:]
plot = None
if '--plot' in args:
    i = args.index('--plot')
    plot = args[i + 1]
    del args[i:i + 2]
ref = load(args[0])
runs = [('default', {k: v for k, v in ref.items() if k[0] == 'keyframe_rf'})]
curves = {}
for arg in args[1:]:
    label, path = arg.split('=', 1)
    runs.append((label, load(path + '/clips.parquet')))
common = set(k[1:] for k in runs[1][1] if k[0] == 'keyframe_rf') if len(runs) > 1 else set(k[1:] for k in runs[0][1])
for _, r in runs:
    common &= set(k[1:] for k in r if k[0] == 'keyframe_rf')
rng = np.random.default_rng(0)
print('setting,k_extra,windows,rmse_x100,chamfer_x100,dtw_x100,jerk_ratio,rmse_over_lerp,rmse_over_default,'
      'diff_vs_default_x100,diff_ci_lo,diff_ci_hi')
for label, r in runs:
    for k in sorted({c[0] for c in common}):
        keys = sorted(c for c in common if c[0] == k)
        get = lambda m, rr=r: np.array([rr[('keyframe_rf',) + c][m] for c in keys])
        lerp = np.array([ref[('lerp',) + c]['rmse'] for c in keys])
        dflt = np.array([ref[('keyframe_rf',) + c]['rmse'] for c in keys])
        d = get('rmse') - dflt
        # Bootstrap over clips (a clip's windows of several seeds are resampled together).
        items = sorted({c[2] for c in keys})
        per_item = np.array([d[[i for i, c in enumerate(keys) if c[2] == it]].mean() for it in items])
        boots = [rng.choice(per_item, len(per_item)).mean() for _ in range(2000)]
        lo, hi = np.percentile(boots, [2.5, 97.5])
        curves.setdefault(label, []).append((k, get('rmse').mean() / lerp.mean()))
        print(f"{label},{k},{len(keys)},{100*get('rmse').mean():.3f},{100*get('chamfer').mean():.3f},"
              f"{100*get('dtw').mean():.3f},{get('jerk_ratio').mean():.2f},{get('rmse').mean()/lerp.mean():.3f},"
              f"{get('rmse').mean()/dflt.mean():.3f},{100*d.mean():.3f},{100*lo:.3f},{100*hi:.3f}")
    if label == 'default':
        for k in sorted({c[0] for c in common}):
            keys = sorted(c for c in common if c[0] == k)
            lerp = np.array([ref[('lerp',) + c] for c in keys])
            print(f"lerp,{k},{len(keys)},{100*np.mean([x['rmse'] for x in lerp]):.3f},"
                  f"{100*np.mean([x['chamfer'] for x in lerp]):.3f},{100*np.mean([x['dtw'] for x in lerp]):.3f},"
                  f"{np.mean([x['jerk_ratio'] for x in lerp]):.2f},1.000,,,,")

if plot:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, pts in curves.items():
        ax.plot([k for k, _ in pts], [r for _, r in pts], marker="o", label=label)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="lerp")
    ax.set_xlabel("K_x (extra keyframes)")
    ax.set_ylabel("RMSE / lerp RMSE (same windows)")
    ax.set_xticks(sorted({k for pts in curves.values() for k, _ in pts}))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(plot, dpi=120)
