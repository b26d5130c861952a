#!/usr/bin/env bash
# Regenerates docs/gallery/ (this folder): every MakeHuman garment of tests/data/patterns
# (mh_*/), and an outfit of two, dressed on the walking avatar and run through `clothsr run` with the generic models,
# rendered at three frames by tools/render.py (Blender, Cycles on the CPU), and the table of
# what each run did (README.md, written by table.py from the runs' logs).
#
#   CLOTHSR=path/to/clothsr bash docs/gallery/make.sh
#
# The runs go to $OUT (default out/gallery, outside version control); a garment whose output
# is there is not run again, nor one that failed or ran out of RUN_TIMEOUT seconds (its .failed
# marker). About a minute a garment to run and one to render, on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${CLOTHSR:-clothsr}
OUT=${OUT:-out/gallery}
FRAMES=${FRAMES:-60}
BPY=${BPY_PYTHON:-.venv-bpy/bin/python}
AVATAR=tests/data/avatars/mh_walk_train_baked_2s.usdc
mkdir -p "$OUT"

# run NAME INPUT [ARGS...]: NAME through `clothsr run` into $OUT/NAME.usdc (standalone, with the
# avatar), checked by `clothsr eval --pred` (cloth inside the body, cloth through cloth), and
# rendered at three frames.
run() {
  local g=$1 input=$2
  shift 2
  if [ ! -f "$OUT/$g.usdc" ] && [ ! -f "$OUT/$g.failed" ]; then
    echo "$(date +%T) $g"
    # A garment that does not dress within the time limit is a row of the table, not the end.
    if ! timeout "${RUN_TIMEOUT:-900}" "$BIN" run "$input" "$@" --layer off --frames "$FRAMES" \
      -o "$OUT/$g.usdc" > "$OUT/$g.log" 2>&1; then
      touch "$OUT/$g.failed"
    fi
  fi
  [ -f "$OUT/$g.usdc" ] || return 0
  [ -f "$OUT/$g.eval.txt" ] || "$BIN" eval --pred "$OUT/$g.usdc" > "$OUT/$g.eval.txt"
  "$BPY" tools/render.py "$OUT/$g.usdc" --frames "1,$((FRAMES / 2)),$FRAMES" --view three-quarter \
    --size 280x350 --samples 16 --fit all -o docs/gallery
}

for spec in tests/data/patterns/mh_*/mh_*_specification.json; do
  run "$(basename "$(dirname "$spec")")" "$spec" --avatar "$AVATAR"
done
# An outfit: two garments on one avatar, in contact with each other.
OUTFIT=tests/data/patterns
"$BIN" convert "$OUTFIT/mh_pants/mh_pants_specification.json" \
  "$OUTFIT/mh_tshirt/mh_tshirt_specification.json" --avatar "$AVATAR" \
  -o "$OUT/outfit_tshirt_pants.usda" > /dev/null
run outfit_tshirt_pants "$OUT/outfit_tshirt_pants.usda"
.venv/bin/python docs/gallery/table.py "$OUT" "$FRAMES" > docs/gallery/README.md
