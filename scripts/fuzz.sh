#!/usr/bin/env bash
# Fuzzes the COLMAP binary readers, the 3DGS PLY reader, the JSON readers (--config, scene
# descriptions, bench grids) and the checkpoint restore with libFuzzer. CI runs it for 30 s
# per harness as the ctest test fuzz_harnesses; run it longer by hand to search deeper.
# Builds a separate clang + ASan/UBSan tree in build/fuzz, seeds the
# corpora with files written by the project (and the fox model's .bin files when
# ../shared/data/fox/sparse/0 exists), then runs each harness for a bounded time, one at a
# time (the machines have 2 cores).
#
# Usage: scripts/fuzz.sh [seconds per harness, default 120] [harness ...]
#   harnesses: colmap_cameras colmap_images colmap_points3D ply json_config json_scene json_grid
#              checkpoint_restore (default: all)
# Environment: DESPLAT_FUZZ_MODEL=<COLMAP sparse dir> overrides the real-model seed source.
#
# Output, all under build/ (which git ignores); the data lives outside the build tree, so
# deleting build/fuzz keeps the corpora:
#   build/fuzz-data/corpus/<harness>/    the growing corpus; kept between runs, so runs accumulate
#   build/fuzz-data/findings/<harness>/  crash-*, timeout-*, oom-* inputs, if any
#   build/fuzz-data/logs/<harness>.log   libFuzzer's full output
#   build/fuzz-data/seeds/               regenerated on every run
# Exit status: 0 when no harness found anything, 1 otherwise. Reproduce a finding with
#   build/fuzz/fuzz/fuzz_<harness> build/fuzz-data/findings/<harness>/crash-...
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-120}
[[ "$seconds" =~ ^[0-9]+$ ]] || { echo "usage: $0 [seconds per harness] [harness ...]" >&2; exit 2; }
shift $(( $# > 0 ? 1 : 0 ))
harnesses=("$@")
all_harnesses="colmap_cameras colmap_images colmap_points3D ply json_config json_scene json_grid checkpoint_restore"
# shellcheck disable=SC2206
[ ${#harnesses[@]} -gt 0 ] || harnesses=($all_harnesses)

build=build/fuzz
data=build/fuzz-data
model=${DESPLAT_FUZZ_MODEL:-../shared/data/fox/sparse/0}

max_len() {  # bytes per input: room for realistic small files, small enough to stay fast
  case "$1" in
    colmap_cameras) echo 4096 ;;
    *) echo 65536 ;;
  esac
}

seed_dir_of() {  # harness -> its seed folder (make_seeds' output, or files kept in the repository)
  case "$1" in
    colmap_cameras) echo "$data/seeds/cameras" ;;
    colmap_images) echo "$data/seeds/images" ;;
    colmap_points3D) echo "$data/seeds/points3D" ;;
    ply) echo "$data/seeds/ply" ;;
    json_config) echo fuzz/seeds/config ;;
    json_scene) echo data/synthetic ;;
    json_grid) echo data/bench ;;
    checkpoint_restore) echo fuzz/seeds/checkpoint ;;
    *) echo "unknown harness '$1' (known: $all_harnesses)" >&2; exit 2 ;;
  esac
}
for h in "${harnesses[@]}"; do seed_dir_of "$h" >/dev/null; done

echo "== configuring and building $build (clang, libFuzzer, ASan + UBSan)"
if [ ! -f "$build/build.ninja" ]; then
  CC=clang CXX=clang++ cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DDESPLAT_BUILD_FUZZERS=ON -DDESPLAT_BUILD_TESTS=OFF -DDESPLAT_BUILD_BENCHMARKS=OFF -DDESPLAT_NATIVE=OFF >/dev/null
fi
targets=(fuzz_make_seeds)
for h in "${harnesses[@]}"; do targets+=("fuzz_$h"); done
ninja -C "$build" "${targets[@]}"

echo "== seeding"
seeds="$data/seeds"
rm -rf "$seeds"
if [ -d "$model" ]; then
  "$build/fuzz/fuzz_make_seeds" "$seeds" "$model"
  for f in cameras images points3D; do  # real files, cut to what the harness reads anyway
    head -c 65536 "$model/$f.bin" >"$seeds/$f/real_prefix.bin"
  done
else
  echo "(no COLMAP model at $model: seeding with synthetic files only)"
  "$build/fuzz/fuzz_make_seeds" "$seeds"
fi

mkdir -p "$data/logs"
status=0
summary=()
for h in "${harnesses[@]}"; do
  corpus="$data/corpus/$h" findings="$data/findings/$h" log="$data/logs/$h.log"
  mkdir -p "$corpus" "$findings"
  echo "== fuzz_$h for ${seconds}s (log: $log)"
  set +e
  "$build/fuzz/fuzz_$h" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -max_len="$(max_len "$h")" -print_final_stats=1 -artifact_prefix="$findings/" \
    "$corpus" "$(seed_dir_of "$h")" >"$log" 2>&1
  rc=$?
  set -e
  stats=$(grep -E '^#[0-9]+[[:space:]]+(DONE|INITED)' "$log" | tail -1 |
    sed -E 's/^#([0-9]+)[[:space:]]+[A-Z]+[[:space:]]+/execs \1 /; s/ lim:.*//') || true
  execs_per_sec=$(sed -nE 's/^stat::average_exec_per_sec:[[:space:]]+//p' "$log")
  found=$(find "$findings" -type f | wc -l)
  summary+=("$h: ${stats:-no stats} | ${execs_per_sec:-?} exec/s | corpus files $(find "$corpus" -type f | wc -l) | findings $found | exit $rc")
  if [ "$rc" -ne 0 ] || [ "$found" -ne 0 ]; then
    status=1
    grep -E 'ERROR|finding|SUMMARY|uncaught|terminate' "$log" | head -20 || true
  fi
done

echo "== summary (${seconds}s each)"
printf '%s\n' "${summary[@]}"
exit $status
