#!/usr/bin/env bash
# Build the real training corpus into OUT: download the registry packages with apt-get, unpack them with dpkg,
# stage their animated assets (`any4d data stage-real`: one folder per asset with package + licence) and import
# every take into the store OUT/store (`any4d data import`). Prints the store summary and the wall time.
#
#   scripts/real_corpus.sh OUT            (ANY4D=path/to/any4d to use a built binary; default: cargo run)
#
# Packages: redeclipse-data (IQM players, MD5 actors), 0ad-data (PMD/PSA animals and units from public.zip),
# ufoai-data (MD2 soldiers, aliens, civilians from 0models.pk3), assimp-testmodels (the animated IQM sample),
# minetest-data and two Minetest mods (B3D player characters and the maid robot; 4 MB together), cube2-data (Cube 2:
# Sauerbraten's IQM player, squirrel, hands and guns, MD5 flag; 173 MB), minetest-mod-homedecor (a turning desk fan),
# gambas3-examples (seven Quake II-style MD2 models of its OpenGL example), blobandconquer-data (an MD2 spider) and
# castle-game-engine-doc (glTF characters, cars and gears of its examples; 257 MB) and supertuxkart-data (SuperTuxKart's
# skinned .spm karts, characters and props with the XML giving their frame ranges; 628 MB). docs/data.md lists every
# package tried and why each was or was not used.
# Never add openarena*, megaglest*, nexuiz*/xonotic*, qt3d* or assimp-testmodels' MD2 files: they are the held-out
# evaluation (the staging step refuses those packages by name and skips the MD2 files).
set -euo pipefail
OUT=${1:?usage: scripts/real_corpus.sh OUT}
PACKAGES=(redeclipse-data 0ad-data ufoai-data assimp-testmodels minetest-data minetest-mod-3d-armor minetest-mod-maidroid
  cube2-data minetest-mod-homedecor gambas3-examples blobandconquer-data castle-game-engine-doc supertuxkart-data)
# Import settings: 16-frame windows every 8 frames, P = 512 FPS tokens (the paper's); the low-poly game meshes
# go down to 128 vertices (the paper's lower bound is 512, which would drop most 0 A.D. animals and UFO:AI
# models). Takes shorter than the window are played round when they loop (--loop-short, docs/method.md §2.6).
FRAMES=${FRAMES:-16}
STRIDE=${STRIDE:-8}
P=${P:-512}
MIN_VERTICES=${MIN_VERTICES:-128}
MAX_VERTICES=${MAX_VERTICES:-4096}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [[ -n "${ANY4D:-}" ]]; then
  any4d() { "$ANY4D" "$@"; }
else
  any4d() { cargo run --quiet --manifest-path "$ROOT/Cargo.toml" -- "$@"; }
fi
start=$(date +%s)
mkdir -p "$OUT/debs" "$OUT/extracted"
OUT=$(cd "$OUT" && pwd)
missing=()
for p in "${PACKAGES[@]}"; do
  compgen -G "$OUT/debs/${p}_*.deb" >/dev/null || missing+=("$p")
done
if ((${#missing[@]})); then
  (cd "$OUT/debs" && apt-get download "${missing[@]}")
fi
for p in "${PACKAGES[@]}"; do
  if [[ ! -d "$OUT/extracted/$p" ]]; then
    deb=$(compgen -G "$OUT/debs/${p}_*.deb" | head -n1)
    dpkg -x "$deb" "$OUT/extracted/$p.tmp" && mv "$OUT/extracted/$p.tmp" "$OUT/extracted/$p"
  fi
done
echo "downloaded and unpacked in $(($(date +%s) - start)) s"
rm -rf "$OUT/staged"
any4d data stage-real "$OUT/extracted" --out "$OUT/staged"
echo "staged in $(($(date +%s) - start)) s"
rm -rf "$OUT/store"
any4d data import "$OUT/staged" --out "$OUT/store" --frames "$FRAMES" --stride "$STRIDE" --p "$P" \
  --min-vertices "$MIN_VERTICES" --max-vertices "$MAX_VERTICES" --loop-short >"$OUT/import.log" || rc=$?
# Exit code 2 means some takes were rejected (listed in import.log); the store is written.
if [[ ${rc:-0} -ne 0 && ${rc:-0} -ne 2 ]]; then cat "$OUT/import.log"; exit "$rc"; fi
grep -v "^  rejected" "$OUT/import.log"
any4d data inspect "$OUT/store" | grep -v "^  rejected" | head -n 30
echo "real corpus: $OUT/store, wall time $(($(date +%s) - start)) s"
