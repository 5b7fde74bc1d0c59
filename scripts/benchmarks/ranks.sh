#!/usr/bin/env bash
# BENCHMARKS.md, "Ranks": one process with 2 threads against 2 MPI ranks with 1 thread each (and
# one process with 1 thread, the compute term of the scaling model), the fox at 1/4, static-only,
# global batch 2, 2,000 views all at that resolution; then the photos' memory per rank at full
# resolution (N = 1, 2; 40 views); then the ordered sum's payload rate (bench_comm_sum).
# Writes docs/benchmarks/ranks.csv and docs/benchmarks/ranks_memory.csv, and prints the terms the
# scaling model (docs/BENCHMARKS.md) takes. Needs mpirun (Open MPI); as root, set
# OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1.
source "$(dirname "$0")/lib.sh"
BENCH=$(realpath -m "${BENCH:-$APPS/../bench}")
MPIRUN=(mpirun --oversubscribe --bind-to none)
common=(--data "$FOX" --downscale 4 --static-only --batch 2 --iterations 2000 --config '{"num_downscales": 0}'
  --checkpoint-every 0)
run() {  # run NAME LAUNCHER... -- desplat_train options
  local name=$1; shift
  local out=$WORK/ranks/$name
  mkdir -p "$WORK/ranks"
  [ -f "$out/metrics.json" ] || "$@" --out "$out" --overwrite > "$out.log" 2>&1
}
run one_2threads "$APPS/desplat_train" "${common[@]}" --threads 2
run ranks2_1thread "${MPIRUN[@]}" -np 2 "$APPS/desplat_train" "${common[@]}" --threads 1
run one_1thread "$APPS/desplat_train" "${common[@]}" --threads 1
csv=$DOCS/ranks.csv
echo "run,ranks,threads_per_rank,seconds,steps_per_s,views_per_s,comm_bytes_per_step,comm_s_per_step,comm_share,psnr,static_gaussians" > "$csv"
for name in one_2threads ranks2_1thread one_1thread; do
  python3 - "$WORK/ranks/$name/metrics.json" "$name" >> "$csv" <<'PY'
import json, sys
m = json.load(open(sys.argv[1])); name = sys.argv[2]
ranks = m["ranks"]["count"]; threads = 2 if name == "one_2threads" else 1
s = m["wall_seconds_this_run"]; views = m["step"]; c = m["communication"]
print(f"{name},{ranks},{threads},{s:.1f},{views / 2 / s:.2f},{views / s:.2f},{c['median_bytes_per_step']:.0f},"
      f"{c['median_seconds_per_step']:.5f},{c['share_of_step_time']:.3f},{m['mean_psnr']:.2f},{m['gaussians']}")
PY
done
mem=$DOCS/ranks_memory.csv
echo "ranks,peak_mb_per_rank" > "$mem"
for n in 1 2; do
  out=$WORK/ranks/memory_np$n
  [ -f "$out/metrics.json" ] || "${MPIRUN[@]}" -np $n "$APPS/desplat_train" --data "$FOX" --static-only --iterations 40 \
    --threads 1 --checkpoint-every 0 --out "$out" --overwrite > "$out.log" 2>&1
  python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); print(sys.argv[2] + "," + " ".join(f"{x:.0f}" for x in m["ranks"]["peak_memory_mb"]))' \
    "$out/metrics.json" $n >> "$mem"
done
"${MPIRUN[@]}" -np 2 "$BENCH/bench_comm_sum" 10
cat "$csv" "$mem"
machine
