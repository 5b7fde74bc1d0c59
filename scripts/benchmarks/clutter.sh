#!/bin/bash
# BENCHMARKS.md, "The clutter benchmark": DeSplat and static-only on clutter_tracks_{000,025,050,100}
# (500×375, 7,000 steps, objects that stay for 3 consecutive views). About 40 min on 2 cores.
source "$(dirname "$0")/lib.sh"
for s in clutter_tracks_000 clutter_tracks_025 clutter_tracks_050 clutter_tracks_100; do synth $s; done
bench clutter_tracks_grid.json clutter_tracks_7k --threads "${THREADS:-2}"
cp "$WORK/clutter_tracks_7k/bench.csv" "$DOCS/clutter_tracks_7k.csv"
cp "$WORK/clutter_tracks_7k/clutter_summary.csv" "$DOCS/clutter_tracks_7k_summary.csv"
cp "$WORK/clutter_tracks_7k/psnr_vs_clutter.png" "$DOCS/clutter_tracks_7k_psnr.png"
cp "$WORK/clutter_tracks_7k/recovered_vs_clutter.png" "$DOCS/clutter_tracks_7k_recovered.png"
cp "$WORK/clutter_tracks_7k/iou_vs_clutter.png" "$DOCS/clutter_tracks_7k_iou.png"
echo "machine: $(machine)"
