#!/usr/bin/env bash
# Regenerates tests/data/models/skirt_lab/ (this folder) from this repository alone:
# GarmentCode's pencil skirt (cotton) dressed on the CC0 walking avatar, simulated at 20 mm and
# 2.5 mm (99,796 fine vertices) through the first 1.5 s of the walk, then the ISR network
# trained on frames 1-30 and measured on frames 31-45 and on a second sequence, then the
# corrector trained on the walk and measured on a third. About 2.5 h on 2 CPU cores.
#
# The fine simulation runs without self-collision (as the sheets' data): with it, its moves
# are capped at half the 2.5 mm mesh's contact margin an iteration, and a leg swinging 5 mm a
# step into the skirt halves most steps (70 s a frame by frame 5).
#
#   CLOTHSR=path/to/clothsr DATA=/tmp/skirt_data bash tests/data/models/skirt_lab/make.sh
set -euo pipefail
cd "$(dirname "$0")/../../../.."
BIN=${CLOTHSR:-clothsr}
DATA=${DATA:-data/skirt}
OUT=${OUT:-tests/data/models/skirt_lab}
PATTERN=tests/data/patterns/mh_pencil_skirt/mh_pencil_skirt_specification.json
# The walk baked to a point cache (every 2nd time code, as the models were trained on).
AVATAR=$DATA/mh_walk_train_baked.usdc
mkdir -p "$DATA"
[ -f "$AVATAR" ] || .venv/bin/python tests/data/avatars/bake.py tests/data/avatars/mh_walk_train.usda "$AVATAR"
COMMON=(--avatar "$AVATAR" --coarse-mm 20 --fine-mm 2.5 --fast --self-collision off)

"$BIN" lab dataset "$PATTERN" "${COMMON[@]}" --frames 45 -o "$DATA/walk"
# A second sequence, never trained on: dressed 2 s into the walk (the garment is carried to
# where the avatar has walked), the walk from 2 s to 3 s.
"$BIN" lab dataset "$PATTERN" "${COMMON[@]}" --clip-start-s 2.0 --frames 30 -o "$DATA/walk_2s"

mkdir -p "$OUT"
# The three balls' ISR recipe (geometry channels, no initialisation input, 4 × 4 pixel blocks)
# on the first 30 frames; 6,000 steps (2.5 min).
"$BIN" lab train isr --data "$DATA/walk" --frames 30 -o "$OUT/isr" \
  --steps 6000 --no-init --unshuffle 4 --depths 2,2,2
# Frames 31-45, which it never saw, and the second sequence.
"$BIN" lab sr --model "$OUT/isr" --data "$DATA/walk" --start-frame 31
"$BIN" lab sr --model "$OUT/isr" --data "$DATA/walk_2s"
# The corrector (session 16): the three balls' recipe (gated decoder, latent 64, 4 blocks)
# on all 45 frames of the walk, then 400 window rollouts (ω = 12 steps), which remove the
# rigid slide that phase 1 alone leaves (see README.md); about 45 min on 2 cores.
"$BIN" lab train corrector --data "$DATA/walk" -o "$OUT/corrector" --steps 2000 --batch 2 \
  --lr-start 1e-3 --lr-end 1e-5 --mp-steps 4 --rollout-iters 400 --window 12 \
  --rollout-lr 1e-4 --take-back 0.5
# Its held-out sequence: dressed 1 s into the walk, 30 frames (about 45 min), then the
# interleaved rollout against the simulation alone.
"$BIN" lab dataset "$PATTERN" "${COMMON[@]}" --clip-start-s 1.0 --frames 30 -o "$DATA/walk_1s"
"$BIN" lab rollout --model "$OUT/corrector" --data "$DATA/walk_1s"
# Session 18: a third unseen sequence (dressed 3 s into the walk), and the corrector on the
# other two it never saw (walk_2s validates fine-tuning runs: see README.md).
"$BIN" lab dataset "$PATTERN" "${COMMON[@]}" --clip-start-s 3.0 --frames 30 -o "$DATA/walk_3s"
"$BIN" lab rollout --model "$OUT/corrector" --data "$DATA/walk_2s"
"$BIN" lab rollout --model "$OUT/corrector" --data "$DATA/walk_3s"

# The manifest names its inputs by absolute path; relative to the repository it travels.
for d in walk walk_1s walk_2s walk_3s; do
  sed "s|$(pwd)/||g" "$DATA/$d/manifest.json" > "$OUT/data_$d.manifest.json"
done
rm -rf "$OUT/isr/checkpoint" "$OUT/corrector/checkpoint"
