#!/usr/bin/env bash
# Contact sheets of rigged characters (docs/method.md §2.8): one clip per template × action below, generator seed 11,
# the clip of a one-clip run with the template and action fixed, rendered by `data render` (the stored, normalised
# clip); sheets/captions.txt keeps each sheet's clip id and caption as `data render` prints them.
#
#   bash experiments/2026-12-06-rigged-characters/sheets.sh      # ANY4D_BIN=... if not target/release/any4d
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=${ANY4D_BIN:-target/release/any4d}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$here/sheets"
: >"$here/sheets/captions.txt"
for pair in biped:walk biped:fall biped:wave multiarm:attack quadruped:walk quadruped:run quadruped:jump \
    insect:walk insect:fall bird:fly bird:walk snake:slither snake:attack; do
  t=${pair%%:*}
  a=${pair##*:}
  "$bin" data synth --family rigged --template "$t" --action "$a" --clips 1 --seed 11 --p 16 --out "$tmp/$t-$a" >/dev/null
  "$bin" data render "$tmp/$t-$a" --out "$tmp/$t-$a.png" | sed "s|$tmp/||g" >>"$here/sheets/captions.txt"
  mv "$tmp/$t-$a.png" "$here/sheets/$t-$a.png"
done
