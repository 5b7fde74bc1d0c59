#!/usr/bin/env bash
# Makes the standard occluded-fox experiment scene: the real fox capture with occluders pasted
# into half of its training views (seed 1, default coverage 5–25 %), ground-truth masks in
# distractor_masks/. Run from anywhere; needs the release build (cmake --build --preset release).
#
#   data/synthetic/make_fox_occluded.sh [OUT_DIR] [more desplat_occlude options, e.g. --overwrite]
#
# OUT_DIR defaults to out/fox_occluded (relative to the repository root). `--track 4` keeps each
# set of occluders in the frame for 4 consecutive training views (the scene of
# tests/test_desplat_evidence.cpp). Train on it with
#   build/release/apps/desplat_train --data out/fox_occluded --downscale 4 --out out/fox_occluded_run
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
out="${1:-$root/out/fox_occluded}"
shift $(( $# > 0 ? 1 : 0 ))
exec "$root/build/release/apps/desplat_occlude" \
  --data "$root/../shared/data/fox" --out "$out" --fraction 0.5 --seed 1 --coverage-min 0.05 --coverage-max 0.25 "$@"
