#!/usr/bin/env bash
# Check the FBX and COLLADA readers against assimp on the animated files of Debian's assimp-testmodels that
# assimp 5.2 (Debian's assimp-utils) exports: each file is read by any4d directly, and exported by assimp to .glb
# and read back by any4d's glTF reader (which reads the first mesh); both go to OBJ folders and every vertex of that
# mesh at a time both sample is matched to its nearest neighbour in ours (assimp splits vertices along UV seams, so
# vertex orders differ), and, for the one-mesh FBX files, every vertex of ours to the nearest of assimp's. The
# .glb's timeline starts at 0 s, ours at the first key: the script reports the best of 0-2 frames of offset. Prints
# per file the largest distance as a fraction of the clip's extent. Needs apt-get, python3 with numpy + scipy.
#
#   scripts/readers_vs_assimp.sh WORK    (ANY4D=path/to/any4d to use a built binary; default: cargo run)
set -euo pipefail
WORK=${1:?usage: scripts/readers_vs_assimp.sh WORK}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [[ -n "${ANY4D:-}" ]]; then
  any4d() { "$ANY4D" "$@"; }
else
  any4d() { cargo run --quiet --manifest-path "$ROOT/Cargo.toml" -- "$@"; }
fi
mkdir -p "$WORK/debs" "$WORK/root"
WORK=$(cd "$WORK" && pwd)
(cd "$WORK/debs" && apt-get download assimp-testmodels assimp-utils libassimp5 libdraco7 2>/dev/null)
for d in "$WORK"/debs/*.deb; do dpkg -x "$d" "$WORK/root"; done
export LD_LIBRARY_PATH="$WORK/root/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
models="$WORK/root/usr/share/assimp/models"
for file in FBX/huesitos.fbx FBX/animation_with_skeleton.fbx Collada/anims_with_full_rotations_between_keys.DAE; do
  name=$(basename "$file" | tr . _)
  rm -rf "$WORK/ours_$name" "$WORK/assimp_$name" "$WORK/$name.glb"
  "$WORK/root/usr/bin/assimp" export "$models/$file" "$WORK/$name.glb" -f glb2 >/dev/null
  any4d data convert "$models/$file" "$WORK/ours_$name" >/dev/null
  any4d data convert "$WORK/$name.glb" "$WORK/assimp_$name" >/dev/null
  info=$(any4d data inspect "$models/$file")
  grep -E "^(frames|vertices|skin)" <<<"$info"
  fps=$(awk '/^takes/ {getline; print $(NF-1)}' <<<"$info")
  python3 - "$WORK/ours_$name" "$WORK/assimp_$name" "$models/$file" "$fps" <<'EOF'
import glob, sys
from fractions import Fraction
import numpy as np
from scipy.spatial import cKDTree

def frames(folder):
    out = []
    for f in sorted(glob.glob(folder + "/*.obj")):
        out.append(np.array([[float(x) for x in l.split()[1:4]] for l in open(f) if l.startswith("v ")]))
    return out

ours, ref = frames(sys.argv[1]), frames(sys.argv[2])
# Our take runs at its own frame rate (`data inspect`); glTF files are read at 30 fps.
fps = Fraction(sys.argv[4])
extent = np.ptp(ours[0], axis=0).max()
both = len(ref[0]) >= len(ours[0])  # the .glb holds all of our mesh, not only its first part
best = None
for shift in range(3):
    worst, times = 0.0, 0
    for k in range(len(ours)):
        t = Fraction(k, 1) / fps
        j = t * 30 + shift
        if j.denominator != 1 or j >= len(ref):
            continue
        a, b = ours[k], ref[int(j)]
        d = cKDTree(a).query(b)[0].max()
        if both:
            d = max(d, cKDTree(b).query(a)[0].max())
        worst, times = max(worst, d / extent), times + 1
    if best is None or worst < best[0]:
        best = (worst, shift, times)
print(f"  {sys.argv[3].split('/')[-1]}: largest distance {best[0]:.2e} of the extent over {best[2]} common times "
      f"(the .glb {best[1]} frame(s) later; {'both ways' if both else 'its first mesh to ours'})")
EOF
done
