#!/usr/bin/env bash
# Regenerates samples/models/three_balls/ (this folder) from this repository alone: training data from
# our own fine simulations of samples/sheet_three_balls.usda (20 mm coarse / 2.5 mm fine), then
# the ISR network and the corrector, each with its config, log and the data manifests it was
# trained on. About 1 h on 2 CPU cores.
#
# The drops are 150 frames (5 s: fall, impact, settling), the held-out one 300 frames (the
# issue's 3000-step rollout). The ISR network trains on all 150 frames, the corrector on the
# first 60.
#
#   CLOTHSR=path/to/clothsr DATA=/tmp/three_balls_data bash samples/models/three_balls/make.sh
set -euo pipefail
cd "$(dirname "$0")/../../.."
BIN=${CLOTHSR:-clothsr}
DATA=${DATA:-data/three_balls}
OUT=${OUT:-samples/models/three_balls}
SCENE=samples/sheet_three_balls.usda
COMMON=(--coarse-mm 20 --fine-mm 2.5 --fast --no-self-collision)

# Two training drops and one held-out test drop (other yaw and offset), as in the paper's §4:
# "we modify the initial states of the cloth pieces to generate distinct simulation data".
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 150 -o "$DATA/train_a"
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 150 --garment-yaw-deg 40 \
  --garment-offset 0.02,0.03,-0.01 -o "$DATA/train_b"
"$BIN" dataset "$SCENE" "${COMMON[@]}" --frames 300 --garment-yaw-deg 20 \
  --garment-offset 0.015,0.01,-0.025 -o "$DATA/test"

mkdir -p "$OUT"
# The ISR on all 150 frames of both drops: the coarse map's geometry channels (the default) and
# no initialisation input (measured better than the paper's previous-frame input, whose own
# errors the network copies forward; see README.md); the Swin body on 4 × 4 pixel blocks
# (within 7 % of the error on 2 × 2 blocks at a third of the time; see README.md).
"$BIN" train isr --data "$DATA/train_a" --data "$DATA/train_b" --frames 150 -o "$OUT/isr" \
  --steps 8000 --no-init --unshuffle 4 --depths 2,2,2 &
# The shipped corrector is session 10's (with session 13's take-back scale of 0.5 and session
# 21's smoothing of 2 rounds added to its config.json), trained by this recipe on the drops of
# the fast solver before session 12's fix; retrained by it on today's drops it measured 1.88×
# the simulation alone over the held-out 299 frames against the shipped one's 1.39× (see
# README.md).
# The gated decoder, no training noise (the defaults), then window rollouts, on the first 60
# frames (two correctors trained on all 150 diverged in the 300-frame rollout, at frames 254
# and 283; this one runs it through).
"$BIN" train corrector --data "$DATA/train_a" --data "$DATA/train_b" --frames 60 -o "$OUT/corrector" \
  --steps 2000 --batch 2 --lr-start 1e-3 --lr-end 1e-5 --mp-steps 4 \
  --rollout-iters 800 --window 12 --rollout-lr 1e-4 --take-back 0.5 --smoothing 2 &
wait

# What the models came from, and no training leftovers in the repository.
for d in train_a train_b test; do
  cp "$DATA/$d/manifest.json" "$OUT/data_$d.manifest.json"
done
rm -rf "$OUT/isr/checkpoint" "$OUT/corrector/checkpoint"
