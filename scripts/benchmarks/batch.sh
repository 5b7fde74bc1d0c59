#!/usr/bin/env bash
# BENCHMARKS.md, "Batches of views": test PSNR/SSIM at --batch 1, 2, 4, 8 and equal views seen
# (3,000, --preset fast, 1 thread) on the fox at 1/4 and on clutter_tracks_050 at 1/4.
# Writes docs/benchmarks/batch.csv (scene, batch, psnr, ssim, static Gaussians, seconds).
source "$(dirname "$0")/lib.sh"
synth clutter_tracks_050
csv=$DOCS/batch.csv
mkdir -p "$WORK/batch"
echo "scene,batch,psnr,ssim,static_gaussians,seconds" > "$csv"
for b in 1 2 4 8; do
  for scene in fox clutter_tracks_050; do
    if [ "$scene" = fox ]; then data=$FOX effects=none; else data=$ROOT/out/$scene effects=distractors; fi
    out=$WORK/batch/$scene-b$b
    [ -f "$out/metrics.json" ] || "$APPS/desplat_train" --data "$data" --downscale 4 --preset fast --effects "$effects" \
      --threads 1 --batch "$b" --checkpoint-every 0 --out "$out" --overwrite > "$out.log" 2>&1
    python3 - "$out/metrics.json" "$scene" "$b" >> "$csv" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
print(f"{sys.argv[2]},{sys.argv[3]},{m['mean_psnr']:.2f},{m['mean_ssim']:.4f},{m['gaussians']},{m['wall_seconds_this_run']:.0f}")
PY
  done
done
machine
