#!/usr/bin/env bash
# Check the FBX reader against assimp on the animated binary FBX files of Debian's assimp-testmodels: each file is
# read by any4d directly, and exported by assimp 5.2 (Debian's assimp-utils) to .glb and read back by any4d's glTF
# reader; both go to OBJ folders and every vertex of every frame at a time both sample is matched to its nearest
# neighbour in the other (assimp splits vertices along UV seams, so vertex orders differ). Prints, per file and
# common time, the largest distance as a fraction of the clip's extent. Needs apt-get, python3 with numpy + scipy.
#
#   scripts/fbx_vs_assimp.sh WORK        (ANY4D=path/to/any4d to use a built binary; default: cargo run)
set -euo pipefail
WORK=${1:?usage: scripts/fbx_vs_assimp.sh WORK}
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
models="$WORK/root/usr/share/assimp/models/FBX"
for name in huesitos animation_with_skeleton; do
  rm -rf "$WORK/ours_$name" "$WORK/assimp_$name" "$WORK/$name.glb"
  "$WORK/root/usr/bin/assimp" export "$models/$name.fbx" "$WORK/$name.glb" -f glb2 >/dev/null
  any4d data convert "$models/$name.fbx" "$WORK/ours_$name" >/dev/null
  any4d data convert "$WORK/$name.glb" "$WORK/assimp_$name" >/dev/null
  info=$(any4d data inspect "$models/$name.fbx")
  grep -E "^(frames|vertices|skin)" <<<"$info"
  fps=$(awk '/^takes/ {getline; print $(NF-1)}' <<<"$info")
  python3 - "$WORK/ours_$name" "$WORK/assimp_$name" "$models/$name.fbx" "$fps" <<'EOF'
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
# The FBX take runs at the file's frame rate (`data inspect`); glTF files are read at 30 fps.
fps = Fraction(sys.argv[4])
extent = np.ptp(ours[0], axis=0).max()
worst = 0.0
for k in range(len(ours)):
    t = Fraction(k, fps)
    if (t * 30).denominator != 1 or int(t * 30) >= len(ref):
        continue
    a, b = ours[k], ref[int(t * 30)]
    d = max(cKDTree(a).query(b)[0].max(), cKDTree(b).query(a)[0].max()) / extent
    worst = max(worst, d)
    print(f"  t = {float(t):.3f} s: largest distance {d:.2e} of the extent")
print(f"  {sys.argv[3].split('/')[-1]}: worst {worst:.2e}")
EOF
done
