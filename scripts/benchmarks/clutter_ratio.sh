#!/bin/bash
# BENCHMARKS.md, "PSNR against the clutter ratio" (the paper's Fig. 7, left): bench.json with
# 0–100 % of the training views cluttered, 1,500 steps at 1/4 resolution. About 35 min on 2 cores.
source "$(dirname "$0")/lib.sh"
for r in 000 020 040 060 080 100; do synth bench_clutter_$r; done
bench clutter_grid.json clutter_ratio --threads "${THREADS:-2}"
cp "$WORK/clutter_ratio/bench.csv" "$DOCS/clutter_ratio.csv"
cp "$WORK/clutter_ratio/psnr_vs_clutter.png" "$DOCS/clutter_ratio_psnr.png"
echo "machine: $(machine)"
