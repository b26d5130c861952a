#!/usr/bin/env bash
# Regenerates samples/models/table/ (this folder) from this repository alone: training data from
# our own fine simulations of samples/sheet_table.usda (20 mm coarse / 2.5 mm fine), then the
# ISR network and the corrector with the three-balls recipe (../three_balls/make.sh), each with
# its config, log and the data manifests it was trained on. About 1 h on 2 CPU cores.
#
#   CLOTHSR=path/to/clothsr DATA=/tmp/table_data bash samples/models/table/make.sh
set -euo pipefail
cd "$(dirname "$0")/../../.."
BIN=${CLOTHSR:-clothsr}
DATA=${DATA:-data/table}
OUT=${OUT:-samples/models/table}
SCENE=samples/sheet_table.usda
COMMON=(--coarse-mm 20 --fine-mm 2.5 --fast --no-self-collision)

# Two training drops and a held-out one (another yaw), and the held-out drop again from a start
# moved by 0.1 mm: the scene's predictability floor (`clothsr rollout --floor`).
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 150 -o "$DATA/train_a"
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 150 --garment-yaw-deg 40 \
  --garment-offset 0.02,0.03,-0.01 -o "$DATA/train_b"
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 90 --garment-yaw-deg 15 -o "$DATA/test"
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 90 --garment-yaw-deg 15 \
  --garment-offset 0.0001,0,0 -o "$DATA/test_floor"

mkdir -p "$OUT"
"$BIN" train isr --data "$DATA/train_a" --data "$DATA/train_b" --frames 150 -o "$OUT/isr" \
  --steps 8000 --no-init --unshuffle 2 --depths 2,2,2 &
"$BIN" train corrector --data "$DATA/train_a" --data "$DATA/train_b" --frames 60 -o "$OUT/corrector" \
  --steps 2000 --batch 2 --lr-start 1e-3 --lr-end 1e-5 --mp-steps 4 \
  --rollout-iters 800 --window 12 --rollout-lr 1e-4 &
wait

for d in train_a train_b test test_floor; do
  cp "$DATA/$d/manifest.json" "$OUT/data_$d.manifest.json"
done
rm -rf "$OUT/isr/checkpoint" "$OUT/corrector/checkpoint"
