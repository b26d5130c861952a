#!/usr/bin/env bash
# Regenerates models/generic/ (this folder), the models `clothsr run` uses when given no
# --models: trained across garments, fabrics, colliders and motions, not on one scene.
#
#   1. The training shots (`clothsr lab scenes --set training`: 24 procedural shots, each a
#      flat garment dropped on a moving or still collider, and 2 short skirts on the walking
#      avatar of tests/data/avatars; see crates/geometry/src/scene/catalogue.rs), TRAIN_FRAMES
#      each, and the held-out shots
#      (`--set held-out`: an unseen garment, collider, motion and fabrics), HELD_FRAMES from
#      three starts each; and a garment people wear that no model saw: GarmentCode's T-shirt
#      (tests/data/patterns/mh_tshirt, silk) on the walk's second second, which no training
#      shot reaches (the avatar shots train on its first), GARMENT_FRAMES from three starts
#      turned and moved as `fit` turns worn garments.
#   2. A fine (2.5 mm) and coarse (20 mm) simulation of each (`clothsr lab dataset`), without
#      self-collision, as every shipped model's data: the fine one in data mode (checked
#      against a tight reference by `clothsr lab converge`), the coarse steps in fast mode.
#   3. The ISR network conditioned on the fabric (`--condition`).
#   4. The coarse model calibrated over all training shots (`clothsr lab calibrate`).
#   5. The held-out figures (`eval` stage): on every held-out start, the whole pipeline with
#      these models (`clothsr lab run`, then `clothsr eval`) beside the simulator's own coarse
#      model upsampled and the ISR on it; the ISR alone on M_int (`clothsr lab sr`); the
#      predictability floor of each shot's first start (`clothsr lab fork`); then the same ISR
#      network trained blind to the fabric, on M_int (for the comparison; not shipped).
#      `summarise.py` gathers them into models.json and held_out.md.
#
# Every step resumes where it stopped: run it again after a kill (FLOOR=0 skips the floors'
# fine simulations, BLIND=0 the blind network). Stages can be run alone:
#
#   CLOTHSR=path/to/clothsr DATA=/path/to/data bash models/generic/make.sh [data|train|eval|all]
#
# Data: about 4 CPU-minutes a training shot on this project's machine; JOBS=2 runs two at once.
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${CLOTHSR:-clothsr}
DATA=${DATA:-data/generic}
OUT=${OUT:-models/generic}
JOBS=${JOBS:-1}
TRAIN_FRAMES=${TRAIN_FRAMES:-30}
# Two seconds a held-out start: in the data mode a 2.5 mm frame of a stiff fabric costs up to a
# minute on 2 cores, and three starts plus a twin of 150 frames each were a day of them.
HELD_FRAMES=${HELD_FRAMES:-60}
GARMENT_FRAMES=${GARMENT_FRAMES:-30}
STAGE=${1:-all}
COMMON=(--coarse-mm 20 --fine-mm 2.5 --fast --self-collision off)
# The avatar of the avatar shots: the walk baked to a point cache (2 s).
AVATAR=tests/data/avatars/mh_walk_train_baked_2s.usdc
# The held-out starts: the shot as written, and turned and moved.
STARTS=("--garment-yaw-deg 0" "--garment-yaw-deg 25 --garment-offset 0.02,0,-0.01"
  "--garment-yaw-deg -35 --garment-offset -0.015,0,0.02")
# The held-out garment's starts: dressed 1 s into the walk, as it is and turned and moved.
GARMENT_STARTS=("--clip-start-s 1 --garment-yaw-deg 0"
  "--clip-start-s 1 --garment-yaw-deg 5 --garment-offset 0.005,0,-0.005"
  "--clip-start-s 1 --garment-yaw-deg -3.75 --garment-offset -0.005,0,0.0075")
GARMENT_SCENE=$DATA/held_out_scenes/tshirt-silk-avatar-walk.usda
# A held-out shot's frames and its start K's flags.
frames_of() { case $1 in *-avatar-*) echo "$GARMENT_FRAMES" ;; *) echo "$HELD_FRAMES" ;; esac; }
start_of() { case $1 in *-avatar-*) echo "${GARMENT_STARTS[$2]}" ;; *) echo "${STARTS[$2]}" ;; esac; }

mkdir -p "$DATA/scenes" "$DATA/held_out_scenes"
"$BIN" lab scenes --set training --frames "$TRAIN_FRAMES" -o "$DATA/scenes" > "$DATA/training.txt"
"$BIN" lab scenes --set held-out --frames "$HELD_FRAMES" -o "$DATA/held_out_scenes" > "$DATA/held_out.txt"
[ -f "$GARMENT_SCENE" ] || "$BIN" convert tests/data/patterns/mh_tshirt/mh_tshirt_specification.json \
  --avatar "$AVATAR" --fabric silk -o "$GARMENT_SCENE" > "$GARMENT_SCENE.log" 2>&1
echo "$GARMENT_SCENE" >> "$DATA/held_out.txt"

# Data set DIR's manifest as the models folder keeps it (in $OUT/data): paths relative to the
# repository, or to the data folder.
kept_manifest() {
  sed "s|$(pwd)/||g; s|$(cd "$DATA" && pwd)/||g" "$1/manifest.json"
}

# Whether data set OUT holds at least FRAMES frames (training reads frames 1..=N only).
complete() {
  [ -f "$1/manifest.json" ] && [ "$(sed -n 's/.*"frames_done": \([0-9]*\),.*/\1/p' \
    "$1/manifest.json")" -ge "$2" ] 2>/dev/null
}

dataset() { # SCENE OUT FRAMES [variation flags…]
  local scene=$1 out=$2 frames=$3
  shift 3
  complete "$out" "$frames" && return 0
  # shellcheck disable=SC2068
  "$BIN" lab dataset "$scene" "${COMMON[@]}" --frames "$frames" $@ -o "$out" \
    > "$out.log" 2>&1
}

if [ "$STAGE" = data ] || [ "$STAGE" = all ]; then
  jobs_list=()
  while read -r scene; do
    name=$(basename "$scene" .usda)
    flags=""
    case $name in *-avatar-*) flags="--avatar $AVATAR" ;; esac
    jobs_list+=("$scene|$DATA/train/$name|$TRAIN_FRAMES|$flags")
  done < "$DATA/training.txt"
  while read -r scene; do
    name=$(basename "$scene" .usda)
    for k in 0 1 2; do
      jobs_list+=("$scene|$DATA/held_out/${name}_s$k|$(frames_of "$name")|$(start_of "$name" $k)")
    done
  done < "$DATA/held_out.txt"
  mkdir -p "$DATA/train" "$DATA/held_out"
  running=0
  for job in "${jobs_list[@]}"; do
    IFS='|' read -r scene out frames flags <<< "$job"
    echo "$(date +%T) $out"
    # shellcheck disable=SC2086
    dataset "$scene" "$out" "$frames" $flags &
    running=$((running + 1))
    if [ "$running" -ge "$JOBS" ]; then
      wait -n
      running=$((running - 1))
    fi
  done
  wait
fi

if [ "$STAGE" = train ] || [ "$STAGE" = all ]; then
  mkdir -p "$OUT"
  train_data=()
  for d in "$DATA"/train/*/; do
    train_data+=(--data "${d%/}")
  done
  # The three balls' ISR recipe (geometry channels, no initialisation input, 4 × 4 pixel
  # blocks), with the fabric and the coarse/fine ratio as inputs; beside it the coarse model
  # best over all training shots, on the settings that mattered on the sample scenes
  # (docs/experiments/three_balls.md), over each shot's first second.
  # Models count as trained on this data only when the folder keeps the manifests of the
  # same training data sets (written once both are trained): data remade (another simulator,
  # another reference) trains them again.
  same_data() {
    for d in "$DATA"/train/*/; do
      cmp -s <(kept_manifest "${d%/}") "$OUT/data/$(basename "$d").manifest.json" || return 1
    done
  }
  trained() { [ -f "$1/model.bpk" ] && [ ! -d "$1/checkpoint" ] && same_data; }
  # Models trained again make every held-out figure of the old ones stale (the floors' fine
  # simulations, which no model enters, stay).
  if ! same_data && [ -d "$DATA/eval" ]; then
    rm -rf "$DATA/isr_blind"
    rm -f "$DATA"/eval/*.{eval,sr,blind}.{csv,txt}
  fi
  pids=()
  if ! trained "$OUT/isr"; then
    "$BIN" lab train isr "${train_data[@]}" -o "$OUT/isr" --steps 12000 --no-init \
      --frames "$TRAIN_FRAMES" \
      --unshuffle 4 --depths 2,2,2 --condition > "$DATA/isr.log" 2>&1 &
    pids+=($!)
  fi
  if [ ! -f "$OUT/coarse.json" ] || ! same_data; then
    "$BIN" lab calibrate "${train_data[@]}" -o "$OUT/coarse.json" \
      --csv "$DATA/calibration.csv" --frames "$((TRAIN_FRAMES - 1))" --compression 1,0.1,0.01 --friction scene,2.5 \
      --wrinkle-bending 0,1 > "$DATA/calibration.log" 2>&1 &
    pids+=($!)
  fi
  for p in "${pids[@]}"; do wait "$p"; done
  rm -rf "$OUT/isr/checkpoint"
  mkdir -p "$OUT/data"
  for d in "$DATA"/train/*/; do
    kept_manifest "${d%/}" > "$OUT/data/$(basename "$d").manifest.json"
  done
fi

if [ "$STAGE" = eval ] || [ "$STAGE" = all ]; then
  EV=$DATA/eval
  mkdir -p "$EV"
  # The simulator's own coarse model with the same ISR: a folder without coarse.json.
  mkdir -p "$EV/paper_model"
  ln -sfn "$(cd "$OUT" && pwd)/isr" "$EV/paper_model/isr"
  evaluate_start() { # SCENE NAME K
    local scene=$1 name=$2 k=$3
    local h=$DATA/held_out/${name}_s$k e=$EV/${name}_s$k
    local frames start
    frames=$(frames_of "$name")
    start=$(start_of "$name" "$k")
    # shellcheck disable=SC2086
    "$BIN" lab sr --model "$OUT/isr" --data "$h" --csv "$e.sr.csv" > "$e.sr.txt"
    # shellcheck disable=SC2086
    "$BIN" lab run "$scene" --models "$OUT" --frames "$frames" $start \
      -o "$e.generic.usdc" --upsampled-out "$e.calibrated_up.usdc" --restart > "$e.run.log" 2>&1
    # shellcheck disable=SC2086
    "$BIN" lab run "$scene" --models "$EV/paper_model" --frames "$frames" $start \
      -o "$e.paper.usdc" --upsampled-out "$e.paper_up.usdc" --restart > "$e.paper.log" 2>&1
    local floor=()
    if [ "$k" = 0 ] && [ "${FLOOR:-1}" = 1 ]; then
      "$BIN" lab fork "$h" --frame 1 -o "$EV/${name}_s0_fork" > "$e.fork.log" 2>&1
      floor=(--floor "$EV/${name}_s0_fork")
    fi
    "$BIN" eval --gt "$h" --pred "$e.generic.usdc" \
      --baseline "paper_upsampled=$e.paper_up.usdc" \
      --baseline "calibrated_upsampled=$e.calibrated_up.usdc" \
      --baseline "paper_with_isr=$e.paper.usdc" "${floor[@]}" \
      --csv "$e.eval.csv" > "$e.eval.txt"
  }
  # JOBS starts at once.
  running=0
  while read -r scene; do
    name=$(basename "$scene" .usda)
    for k in 0 1 2; do
      [ -f "$EV/${name}_s$k.eval.csv" ] && continue
      # A start whose data is still being made is evaluated on a later run.
      if ! complete "$DATA/held_out/${name}_s$k" "$(frames_of "$name")"; then
        echo "$(date +%T) ${name}_s$k: data not complete, not evaluated"
        continue
      fi
      evaluate_start "$scene" "$name" "$k" &
      running=$((running + 1))
      if [ "$running" -ge "$JOBS" ]; then
        wait -n
        running=$((running - 1))
      fi
    done
  done < "$DATA/held_out.txt"
  wait
  # The same network blind to the fabric, for the comparison in held_out.md (not shipped).
  if [ "${BLIND:-1}" = 1 ]; then
    train_data=()
    for d in "$DATA"/train/*/; do
      train_data+=(--data "${d%/}")
    done
    if ! { [ -f "$DATA/isr_blind/model.bpk" ] && [ ! -d "$DATA/isr_blind/checkpoint" ]; }; then
      "$BIN" lab train isr "${train_data[@]}" -o "$DATA/isr_blind" --steps 12000 --no-init \
        --frames "$TRAIN_FRAMES" \
        --unshuffle 4 --depths 2,2,2 > "$DATA/isr_blind.log" 2>&1
      rm -rf "$DATA/isr_blind/checkpoint"
    fi
    while read -r scene; do
      name=$(basename "$scene" .usda)
      for k in 0 1 2; do
        e=$EV/${name}_s$k
        [ -f "$e.blind.csv" ] && continue
        complete "$DATA/held_out/${name}_s$k" "$(frames_of "$name")" || continue
        "$BIN" lab sr --model "$DATA/isr_blind" --data "$DATA/held_out/${name}_s$k" \
          --csv "$e.blind.csv" > "$e.blind.txt"
      done
    done < "$DATA/held_out.txt"
  fi
  python3 models/generic/summarise.py "$DATA" "$OUT" "$HELD_FRAMES" "$GARMENT_FRAMES"
  # What the models were measured on (the training sets' manifests are kept by `train`).
  mkdir -p "$OUT/data"
  for d in "$DATA"/held_out/*/; do
    name=$(basename "$d")
    complete "${d%/}" "$(frames_of "${name%_s[0-9]}")" || continue
    kept_manifest "${d%/}" > "$OUT/data/$name.manifest.json"
  done
fi
