#!/usr/bin/env bash
# Long runs: FRAMES (1,000) frames of the whole pipeline on each sample scene, each with its
# shipped models (the generic ones for the sphere), the pencil skirt on the avatar's walk played
# forward and back (tools/bench/pingpong_walk.py); then `clothsr eval --pred` checks every output
# frame: no point that is not finite, no fine vertex inside a body, the largest move of a
# vertex in one frame. Peak memory (GNU time) beside each run.
#
#   CLOTHSR=path/to/clothsr OUT=DIR bash tools/bench/long_runs.sh
#
# A killed run resumes where it stopped; a finished one is skipped. Results: DIR/summary.txt.
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${CLOTHSR:-clothsr}
OUT=${OUT:-long_runs}
FRAMES=${FRAMES:-1000}
PY=${PYTHON:-.venv/bin/python}
mkdir -p "$OUT"
walk=$OUT/walk_pingpong_$FRAMES.usdc
[ -f "$walk" ] || "$PY" tools/bench/pingpong_walk.py tests/data/avatars/mh_walk_train.usda "$walk" "$FRAMES"

long_run() { # NAME ARGS…
  local name=$1
  shift
  [ -f "$OUT/$name.check" ] && return 0
  /usr/bin/time -v "$BIN" run "$@" --frames "$FRAMES" --layer off -o "$OUT/$name.usdc" \
    > "$OUT/$name.log" 2>&1
  "$BIN" eval --pred "$OUT/$name.usdc" > "$OUT/$name.check.tmp"
  mv "$OUT/$name.check.tmp" "$OUT/$name.check"
}
long_run sphere samples/sheet_sphere.usda
long_run three_balls samples/sheet_three_balls.usda --models samples/models/three_balls
long_run table samples/sheet_table.usda --models samples/models/table
long_run skirt tests/data/patterns/mh_pencil_skirt/mh_pencil_skirt_specification.json \
  --avatar "$walk" --models samples/models/skirt

for name in sphere three_balls table skirt; do
  echo "== $name"
  cat "$OUT/$name.check"
  grep -E "Maximum resident|Elapsed" "$OUT/$name.log" | sed 's/^\s*/  /'
  echo "  warnings: $(grep -c WARN "$OUT/$name.log" || true)"
done | tee "$OUT/summary.txt"
