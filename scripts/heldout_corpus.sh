#!/usr/bin/env bash
# Build the held-out real evaluation store into OUT: never train or tune on it (README, "Held-out data"). Downloads
# openarena-data (the player models' MD3 vertex animations, sarge and sorceress: lower and upper body) and
# assimp-testmodels (its two MD2 models, faerie and sydney) with apt-get, unpacks them, copies those files into
# OUT/files and imports every take as 16-frame windows every 16 frames with P = 128 FPS tokens (the shipped small
# VAE's) into OUT/store. Score it whole with `any4d eval run --data OUT/store --split all`.
#
#   scripts/heldout_corpus.sh OUT         (ANY4D=path/to/any4d to use a built binary; default: cargo run)
set -euo pipefail
OUT=${1:?usage: scripts/heldout_corpus.sh OUT}
FRAMES=${FRAMES:-16}
STRIDE=${STRIDE:-16}
P=${P:-128}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [[ -n "${ANY4D:-}" ]]; then
  any4d() { "$ANY4D" "$@"; }
else
  any4d() { cargo run --quiet --manifest-path "$ROOT/Cargo.toml" -- "$@"; }
fi
mkdir -p "$OUT/debs" "$OUT/extracted"
OUT=$(cd "$OUT" && pwd)
for p in openarena-data assimp-testmodels; do
  compgen -G "$OUT/debs/${p}_*.deb" >/dev/null || (cd "$OUT/debs" && apt-get download "$p")
  if [[ ! -d "$OUT/extracted/$p" ]]; then
    dpkg -x "$(compgen -G "$OUT/debs/${p}_*.deb" | head -n1)" "$OUT/extracted/$p.tmp"
    mv "$OUT/extracted/$p.tmp" "$OUT/extracted/$p"
  fi
done
rm -rf "$OUT/files" "$OUT/pk3" "$OUT/store"
mkdir -p "$OUT/files" "$OUT/pk3"
pak="$OUT/extracted/openarena-data/usr/share/games/openarena/baseoa/pak0.pk3"
# Only the players' first-LOD bodies (lower.md3, upper.md3): the _1/_2 files are coarser copies, heads do not move.
# They are copied without animation.cfg: each file stays one take of all its frames (as when the held-out
# figures of the experiments were measured), not one take per animation.
unzip -q -o "$pak" 'models/players/*/lower.md3' 'models/players/*/upper.md3' -d "$OUT/pk3"
for f in "$OUT"/pk3/models/players/*/{lower,upper}.md3; do
  cp "$f" "$OUT/files/$(basename "$(dirname "$f")")_$(basename "$f")"
done
cp "$OUT"/extracted/assimp-testmodels/usr/share/assimp/models/MD2/*.md2 "$OUT/files/"
rc=0
any4d data import "$OUT/files" --out "$OUT/store" --frames "$FRAMES" --stride "$STRIDE" --p "$P" \
  --min-vertices 256 --max-vertices 4096 >"$OUT/import.log" || rc=$?
# Exit code 2: some takes were rejected (shorter than a window; listed in import.log); the store is written.
if [[ $rc -ne 0 && $rc -ne 2 ]]; then cat "$OUT/import.log"; exit "$rc"; fi
any4d data inspect "$OUT/store" | head -n 12
