#!/bin/bash
# BENCHMARKS.md, "The fox and the occluded fox": the defaults (DeSplat where the capture has
# transients) against --static-only on the clean fox and on fox_occ100 (occluders in 40 of its
# 43 training views, staying for 3 consecutive views), --downscale 4, 7,000 steps, seed 0,
# two threads, one run at a time. Writes docs/benchmarks/fox.csv. About 10 min on 2 cores.
source "$(dirname "$0")/lib.sh"
occ=$WORK/fox_occ100
[ -f "$occ/occluders.json" ] || "$APPS/desplat_occlude" --data "$FOX" --out "$occ" --fraction 1.0 --seed 7 \
  --coverage-min 0.08 --coverage-max 0.2 --track 3 --overwrite > /dev/null
for scene in fox fox_occ100; do
  data=$FOX; [ $scene = fox_occ100 ] && data=$occ
  for mode in defaults static-only; do
    flag=(); [ $mode = static-only ] && flag=(--static-only)
    out=$WORK/fox_${scene}_$mode
    /usr/bin/time -f %e -o "$out.time" "$APPS/desplat_train" --data "$data" --downscale 4 --iterations 7000 \
      --threads 2 --checkpoint-every 0 --out "$out" --overwrite "${flag[@]}" > "$out.log" 2>&1
  done
done
python3 - "$WORK" "$DOCS/fox.csv" <<'PY'
import csv, json, os, sys
work, out = sys.argv[1], sys.argv[2]
with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["scene", "run", "psnr", "ssim", "mask_iou", "static_gaussians", "distractor_gaussians", "wall_seconds"])
    for scene in ["fox", "fox_occ100"]:
        for mode in ["defaults", "static-only"]:
            d = os.path.join(work, f"fox_{scene}_{mode}")
            m = json.load(open(os.path.join(d, "metrics.json")))
            iou = (m.get("distractor_masks") or {}).get("mean_iou", "")
            wall = open(d + ".time").read().split()[-1]
            w.writerow([scene, mode, round(m["mean_psnr"], 2), round(m["mean_ssim"], 4), iou,
                        m["cost"]["static_gaussians"], m["cost"]["distractor_gaussians"], wall])
print(open(out).read())
PY
echo "machine: $(machine)"
