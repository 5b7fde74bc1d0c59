# Shared by the scripts in scripts/benchmarks/ (sourced, not run). Each script regenerates one
# table of docs/BENCHMARKS.md: it builds nothing, trains with the apps in $APPS, works in
# $WORK and copies the CSV and plots the page shows into docs/benchmarks/.
#   APPS  the built apps (default build/release/apps)
#   WORK  scratch folder for scenes and runs (default out/benchmarks); an interrupted script
#         resumes there (desplat_bench --resume)
# The grids in data/bench/ name their scenes relative to themselves, as out/<scene>, so the
# scenes are generated into the repository's out/ folder.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
APPS=$(realpath -m "${APPS:-$ROOT/build/release/apps}")
WORK=$(realpath -m "${WORK:-$ROOT/out/benchmarks}")
DOCS=$ROOT/docs/benchmarks
FOX=${DESPLAT_FOX_DIR:-$ROOT/../shared/data/fox}
mkdir -p "$WORK" "$DOCS" "$ROOT/out"
[ -x "$APPS/desplat_train" ] || { echo "no desplat_train in $APPS: build first (cmake --build --preset release)" >&2; exit 1; }

# synth NAME: generate data/synthetic/NAME.json into out/NAME once.
synth() {
  [ -f "$ROOT/out/$1/scene.json" ] || "$APPS/desplat_synth" --scene "$ROOT/data/synthetic/$1.json" --out "$ROOT/out/$1" --overwrite -q
}

# bench GRID OUT [desplat_bench options]: run a grid from data/bench/ into $WORK/OUT.
bench() {
  local grid=$1 out=$2; shift 2
  local resume=()
  [ -f "$WORK/$out/bench.csv" ] && resume=(--resume)
  "$APPS/desplat_bench" --grid "$ROOT/data/bench/$grid" --out "$WORK/$out" "${resume[@]}" "$@"
}

# machine: the line BENCHMARKS.md records for a table (CPU, cores, vector ISA, date).
machine() {
  local cpu isa=portable
  cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
  grep -qw avx2 /proc/cpuinfo && isa=AVX2
  grep -qw avx512f /proc/cpuinfo && isa=AVX-512
  echo "$cpu, $(nproc) cores, $isa, $(date -u +%F)"
}
