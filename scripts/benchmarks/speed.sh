#!/bin/bash
# BENCHMARKS.md, "Speed": the fox static-only at 1/2 resolution for 7,000 steps, two threads,
# and the rasterizer's forward + backward in bench_raster. Run it alone on the machine.
source "$(dirname "$0")/lib.sh"
out=$WORK/speed_fox
/usr/bin/time -f "wall %e s, peak RSS %M kB" "$APPS/desplat_train" --data "$FOX" --static-only --downscale 2 \
  --iterations 7000 --threads 2 --checkpoint-every 0 --out "$out" --overwrite | tail -3
python3 - "$out/metrics.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1])); t = m["median_step_seconds_full_resolution"]
print(f"test PSNR {m['mean_psnr']:.2f} dB, SSIM {m['mean_ssim']:.4f}, {m['gaussians']} Gaussians, "
      f"training {m['wall_seconds_this_run']:.1f} s, median full-resolution step {1000 * t['total']:.1f} ms "
      f"(forward {1000 * t['forward']:.1f}, backward {1000 * t['backward']:.1f}), {t['kernel_isa']}")
PY
bench_dir=$(dirname "$APPS")/bench
DESPLAT_BENCH_PLY=$out/point_cloud.ply "$bench_dir/bench_raster" --benchmark_filter='BM_ForwardBackward' \
  --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
echo "machine: $(machine)"
