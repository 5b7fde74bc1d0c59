#!/bin/bash
# BENCHMARKS.md, "The effect bench": the eight synthetic combinations of transients, per-photo
# exposure and sky, each trained with all eight effect sets (--preset fast at 160×120, two runs
# at a time, one thread each), plus what --effects auto chooses. About 2 h on 2 cores.
source "$(dirname "$0")/lib.sh"
"$ROOT/data/synthetic/effects/run_bench.sh" "$APPS" "$WORK/effects"
python3 "$ROOT/data/synthetic/effects/summarize.py" "$WORK/effects/runs" "$DOCS/effects_bench"
rm -f "$DOCS/effects_bench.md"   # the table is in BENCHMARKS.md
echo "machine: $(machine)"
