#!/bin/bash
# The effect benchmark (docs/BENCHMARKS.md): the eight combinations of
# {transients, exposure and white balance, sky} from desplat_synth, each trained with every
# one of the eight effect sets (none, d, a, b, da, db, ab, dab: d distractors, a appearance,
# b background), two runs at a time, one thread each, 3,000 steps of --preset fast at full
# resolution (160x120). `--effects auto` is not trained again: on all eight scenes it chooses
# the simulated set and then trains what `--effects` naming that set trains, bit for bit
# (docs/METHOD.md §10), so summarize.py reads its row from that set's run.
# What auto chooses (and how long its probe takes) is recorded by a 1-step auto run per scene.
# A run whose metrics.json exists is kept, so an interrupted bench resumes where it stopped.
# usage: run_bench.sh APPS_DIR WORK_DIR     (then summarize.py WORK_DIR/runs OUT_PREFIX)
set -euo pipefail
apps=$(realpath "$1"); work=$(realpath -m "$2"); here=$(dirname "$(realpath "$0")")
mkdir -p "$work/scenes" "$work/runs"
for s in none t e s te ts es tes; do
  [ -f "$work/scenes/$s/scene.json" ] && continue
  "$apps/desplat_synth" --scene "$here/$s.json" --out "$work/scenes/$s" --overwrite > "$work/scenes/$s.log"
done
echo '{"num_downscales": 0}' > "$work/runs/full_res.json"
{
  for s in none t e s te ts es tes; do
    for code in none d a b da db ab dab; do
      [ -f "$work/runs/${s}_$code/metrics.json" ] && continue
      e=""
      [[ $code == *d* ]] && e+=distractors,
      [[ $code == *a* ]] && e+=appearance,
      [[ $code == *b* ]] && e+=background,
      e=${e%,}; e=${e:-none}
      echo "$s $code $e"
    done
  done
  for s in none t e s te ts es tes; do
    [ -f "$work/runs/${s}_autodecision/metrics.json" ] || echo "$s autodecision auto --iterations 1"
  done
} | xargs -P 2 -L 1 bash -c 's=$0 l=$1 e=$2; shift 2; /usr/bin/time -v "'"$apps"'/desplat_train" --data "'"$work"'/scenes/$s" \
  --preset fast --config "'"$work"'/runs/full_res.json" --effects $e --threads 1 --checkpoint-every 0 \
  --out "'"$work"'/runs/${s}_$l" --overwrite "$@" > "'"$work"'/runs/${s}_$l.log" 2>&1'
