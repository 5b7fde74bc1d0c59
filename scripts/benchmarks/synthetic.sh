#!/bin/bash
# BENCHMARKS.md, "The RobustNeRF-like scene": DeSplat against static-only on bench.json at 1/2
# resolution for 7,000 steps, and the reduced 2,000-step grid. About 25 min on 2 cores.
source "$(dirname "$0")/lib.sh"
synth bench
bench bench_grid_7k_half.json synthetic_7k --threads "${THREADS:-2}"
bench bench_grid_quick.json synthetic_quick --threads "${THREADS:-2}"
cp "$WORK/synthetic_7k/bench.csv" "$DOCS/synthetic_7k.csv"
cp "$WORK/synthetic_quick/bench.csv" "$DOCS/synthetic_quick.csv"
for m in psnr ssim iou; do
  cp "$WORK/synthetic_7k/bench_${m}_vs_time.png" "$DOCS/synthetic_7k_${m}_vs_time.png"
  cp "$WORK/synthetic_quick/bench_${m}_vs_time.png" "$DOCS/synthetic_quick_${m}_vs_time.png"
done
echo "machine: $(machine)"
