#!/bin/bash
# Issue 15's effect benchmark (docs/bench/issue15_effects.md): the eight combinations of
# {transients, exposure and white balance, sky} from desplat_synth, each trained with
# --effects auto, none, the simulated set ("true") and all three, two runs at a time,
# one thread each, 3,000 steps of --preset fast at full resolution (160x120).
# usage: run_bench.sh APPS_DIR WORK_DIR     (then summarize.py WORK_DIR/runs OUT_PREFIX)
set -euo pipefail
apps=$(realpath "$1"); work=$(realpath -m "$2"); here=$(dirname "$(realpath "$0")")
mkdir -p "$work/scenes" "$work/runs"
for s in none t e s te ts es tes; do
  "$apps/desplat_synth" --scene "$here/$s.json" --out "$work/scenes/$s" --overwrite > "$work/scenes/$s.log"
done
echo '{"num_downscales": 0}' > "$work/runs/full_res.json"
all=distractors,appearance,background
{
  for s in none t e s te ts es tes; do echo "$s auto auto"; echo "$s none none"; done
  # The simulated set and all three, where auto is not already that set (auto turns
  # distractors on whatever the scene: no test for transients before training is reliable).
  for s in none t e s te ts; do echo "$s all $all"; done
  echo "e true appearance"; echo "s true background"; echo "es true appearance,background"
} | xargs -P 2 -L 1 bash -c 's=$0 l=$1 e=$2; /usr/bin/time -v "'"$apps"'/desplat_train" --data "'"$work"'/scenes/$s" \
  --preset fast --config "'"$work"'/runs/full_res.json" --effects $e --threads 1 --checkpoint-every 0 \
  --out "'"$work"'/runs/${s}_$l" --overwrite > "'"$work"'/runs/${s}_$l.log" 2>&1'
