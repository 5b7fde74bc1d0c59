#!/bin/bash
# BENCHMARKS.md, "Presets": each preset's whole run on the fox (--downscale 4) and on
# clutter_tracks_050 (--downscale 4), scored every 500 steps. The grids include --preset paper,
# which grows millions of Gaussians: set SKIP_PAPER=1 to train only fast and default.
source "$(dirname "$0")/lib.sh"
synth clutter_tracks_050
for g in fox synth; do
  grid=$ROOT/data/bench/presets_${g}_grid.json
  if [ "${SKIP_PAPER:-0}" = 1 ]; then
    # The same grid without the paper run, beside the original so its relative scene paths hold.
    sed '/"name": "paper"/d' "$grid" | sed -z 's/,\n  \]/\n  ]/' > "$ROOT/data/bench/.presets_${g}_no_paper.json"
    grid=$ROOT/data/bench/.presets_${g}_no_paper.json
  fi
  out=$WORK/presets_$g
  resume=(); [ -f "$out/bench.csv" ] && resume=(--resume)
  "$APPS/desplat_bench" --grid "$grid" --out "$out" "${resume[@]}"
  cp "$out/bench.csv" "$DOCS/presets_$g.csv"
  scene=$(head -2 "$out/bench.csv" | tail -1 | cut -d, -f1)
  cp "$out/${scene}_psnr_vs_time.png" "$DOCS/presets_${g}_psnr_vs_time.png"
done
rm -f "$ROOT"/data/bench/.presets_*_no_paper.json
echo "machine: $(machine)"
