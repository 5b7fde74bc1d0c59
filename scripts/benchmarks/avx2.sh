#!/bin/bash
# BENCHMARKS.md, "Speed", "AVX2 and AVX-512 on one machine": the README's first command and
# the rasterizer's forward + backward with the AVX2 pixel loops against the AVX-512 ones, on
# an AVX-512 CPU, and with a whole build for AVX2 CPUs (x86-64-v3: AVX2 and FMA, no AVX-512),
# as an AVX2-only machine would run it. Run it alone on the machine.
#   AVX2_BUILD  that build (default build/avx2; made here when missing:
#               cmake -S . -B build/avx2 -G Ninja -DCMAKE_BUILD_TYPE=Release -DDESPLAT_NATIVE=OFF
#               -DCMAKE_CXX_FLAGS=-march=x86-64-v3 && cmake --build build/avx2
#               --target desplat_train bench_raster)
# With `perf` installed it also records where the AVX2 training run's time goes
# ($WORK/avx2/train_avx2.perf; `perf report -i … --sort symbol`).
source "$(dirname "$0")/lib.sh"
AVX2_BUILD=$(realpath -m "${AVX2_BUILD:-$ROOT/build/avx2}")
R=$WORK/avx2
mkdir -p "$R"
grep -qw avx512f /proc/cpuinfo || { echo "this CPU has no AVX-512: nothing to compare against" >&2; exit 1; }
if [ ! -x "$AVX2_BUILD/apps/desplat_train" ] || [ ! -x "$AVX2_BUILD/bench/bench_raster" ]; then
  cmake -S "$ROOT" -B "$AVX2_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release -DDESPLAT_NATIVE=OFF \
    -DCMAKE_CXX_FLAGS=-march=x86-64-v3 > "$R/cmake.log"
  cmake --build "$AVX2_BUILD" --target desplat_train bench_raster > "$R/build.log"
fi
BENCH=$(dirname "$APPS")/bench/bench_raster

# The README's first command: native build (AVX-512 loops), then the AVX2 build and loops.
train() {  # NAME APPS_DIR [extra options]
  local name=$1 apps=$2; shift 2
  /usr/bin/time -v -o "$R/$name.time" "$apps/desplat_train" --data "$FOX" --downscale 4 --iterations 7000 \
    --out "$R/$name" --overwrite "$@" > "$R/$name.log" 2>&1
  python3 - "$R/$name" "$name" <<'PY'
import json, re, sys
d, name = sys.argv[1:]
m = json.load(open(f"{d}/metrics.json"))
wall = open(f"{d}.time").read()
rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", wall).group(1)) / 1024
probe = m["effects"]["evidence"].get("transients", {}).get("probe_seconds", 0)
t = m["median_step_seconds_full_resolution"]
eta = ", ".join(f"{e['percent']} %: {100 * e['error']:+.0f} %" for e in m["eta_accuracy"])
print(f"| {name} | {m['wall_seconds_this_run']:.1f} s + probe {probe:.1f} s | {m['mean_psnr']:.2f} dB / "
      f"{m['mean_ssim']:.4f} | {m['gaussians']:,} | {1000 * t['total']:.1f} ms (forward {1000 * t['forward']:.1f}, "
      f"backward {1000 * t['backward']:.1f}) | {t['ns_per_pair_forward_backward']:.2f} | {rss:.0f} MB | {eta} |")
PY
}
echo "| run | training | test PSNR / SSIM | Gaussians | median full-size step | ns/pair fwd+bwd | peak RSS | ETA error |"
echo "|---|---|---|---|---|---|---|---|"
train native "$APPS"
train avx2 "$AVX2_BUILD/apps" --config '{"kernel_isa": "avx2"}'

# Forward + backward of the trained fox (the native run's model) at 540×960, 270×480 and
# 135×240, and 500,000 random Gaussians at 512×384; 1 and 2 threads; median of 5.
echo
echo "| build | scene | threads | AVX2 loops: ms, ns/pair | AVX-512 loops: ms, ns/pair |"
echo "|---|---|---|---|---|"
for build in native avx2; do
  bench=$BENCH; [ $build = avx2 ] && bench=$AVX2_BUILD/bench/bench_raster
  DESPLAT_BENCH_PLY=$R/native/point_cloud.ply "$bench" --benchmark_filter='BM_ForwardBackward/scene:(500000|1|2|4)/threads:(1|2)/isa:(2|3)/' \
    --benchmark_repetitions=5 --benchmark_report_aggregates_only=true --benchmark_format=json 2>/dev/null > "$R/bench_$build.json"
  python3 - "$R/bench_$build.json" "$build" <<'PY'
import json, re, sys
rows = {}
for b in json.load(open(sys.argv[1]))["benchmarks"]:
    if b.get("aggregate_name") != "median": continue
    scene, threads, isa = re.search(r"scene:(\d+)/threads:(\d+)/isa:(\d+)", b["name"]).groups()
    rows.setdefault((scene, threads), {})[isa] = f"{b['real_time']:.1f}, {1e9 * b['time_per_pair']:.2f}"
names = {"1": "fox 540×960", "2": "fox 270×480", "4": "fox 135×240", "500000": "500k random, 512×384"}
for (scene, threads), r in rows.items():
    print(f"| {sys.argv[2]} | {names[scene]} | {threads} | {r.get('2', '—')} | {r.get('3', '—')} |")
PY
done
if command -v perf > /dev/null; then
  perf record -q -F 300 -o "$R/train_avx2.perf" "$AVX2_BUILD/apps/desplat_train" --data "$FOX" --downscale 4 \
    --iterations 7000 --config '{"kernel_isa": "avx2"}' --out "$R/avx2_perf" --overwrite > /dev/null 2>&1
  # awk, not head: it reads to the end, so perf never dies of a closed pipe (set -o pipefail).
  perf report -i "$R/train_avx2.perf" --no-children --sort symbol --stdio 2> /dev/null | awk '/%/ && n++ < 20'
fi
echo "machine: $(machine)"
