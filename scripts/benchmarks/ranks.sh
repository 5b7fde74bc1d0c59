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
cat "$csv" "$mem"
# The scaling model (docs/BENCHMARKS.md, "Ranks"), from the terms measured above: the compute per
# view (one rank, 1 thread), the payload bytes per step per Gaussian, and the ordered sum's
# payload rate here; 10 and 100 Gbit/s links at their line rate.
"${MPIRUN[@]}" -np 2 "$BENCH/bench_comm_sum" 10 | tee "$WORK/ranks/comm_sum.txt"
python3 - "$csv" "$WORK/ranks/comm_sum.txt" "$DOCS/ranks_model.csv" <<'PY'
import csv, itertools, math, re, sys
rows = {r["run"]: r for r in csv.DictReader(open(sys.argv[1]))}
one, two = rows["one_1thread"], rows["ranks2_1thread"]
t_view = 1 / float(one["views_per_s"])                       # s per view, one rank, 1 thread
gaussians = float(two["static_gaussians"])
bytes_per_gaussian = float(two["comm_bytes_per_step"]) / gaussians  # at the run's final count
here = float(re.search(r"([0-9.]+) GB/s", open(sys.argv[2]).read()).group(1)) * 1e9

def expected_max(views, ranks):  # E[max over ranks of the batch's views on it], uniform draws
    if ranks == 1: return views
    total = 0.0
    # multinomial over ranks: enumerate compositions for small cases, else a normal approximation
    if ranks ** views <= 2e6:
        for draw in itertools.product(range(ranks), repeat=views):
            total += max(draw.count(r) for r in range(ranks))
        return total / ranks ** views
    mean, sd = views / ranks, math.sqrt(views / ranks * (1 - 1 / ranks))
    return mean + sd * math.sqrt(2 * math.log(ranks))

def step(ranks, views, rate, g=gaussians):
    # the ordered sum: rank 0 receives (N-1) payloads, then a broadcast of log2 N rounds
    comm = 0.0 if ranks == 1 else ((ranks - 1) + math.ceil(math.log2(ranks))) * bytes_per_gaussian * g / rate
    return expected_max(views, ranks) * t_view + comm, comm

predicted, _ = step(2, 2, here)
measured = 1 / float(two["steps_per_s"])
print(f"t_view {t_view*1e3:.2f} ms, {bytes_per_gaussian:.1f} B per Gaussian per step, ordered sum {here/1e9:.3f} GB/s here")
print(f"2 ranks, batch 2: predicted {2/predicted:.2f} views/s, measured {2/measured:.2f} views/s "
      f"({100*(2/predicted)/(2/measured)-100:+.0f} %)")
with open(sys.argv[3], "w") as out:
    w = csv.writer(out)
    w.writerow(["network", "ranks", "batch", "views_per_s", "efficiency", "comm_share", "gaussians_where_comm_equals_compute"])
    for name, rate in (("10 Gbit/s", 1.25e9), ("100 Gbit/s", 12.5e9)):
        for n in (1, 2, 4, 8, 16, 32, 64):
            b = 2 * n
            t, comm = step(n, b, rate)
            eff = (b / t) / (n / t_view)
            per_g = 0 if n == 1 else ((n - 1) + math.ceil(math.log2(n))) * bytes_per_gaussian / rate
            g_star = "" if n == 1 else f"{expected_max(b, n) * t_view / per_g:.0f}"
            w.writerow([name, n, b, f"{b/t:.1f}", f"{eff:.2f}", f"{comm/t:.2f}", g_star])
print(open(sys.argv[3]).read())
PY
machine
