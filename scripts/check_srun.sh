#!/usr/bin/env bash
# desplat_train launched by Slurm's srun, on a one-node cluster made on this machine, against
# mpirun (README, "More than one machine"; docs/BENCHMARKS.md, "Ranks"). Not part of ctest: it
# needs root and leaves munged, slurmctld and slurmd running.
#
# Usage: scripts/check_srun.sh [setup|check|all] [BUILD_DIR] [SOURCE_DIR] [WORK_DIR]
#   setup  install (if missing) and start munge and a one-node Slurm cluster on localhost; idempotent
#   check  train the tiny_distractors scene (the mpirun equivalence test's, tests/mpi/train_ranks.sh)
#          with 2 ranks under srun and under mpirun and compare; a photo only rank 1 holds damaged
#          must end the srun job with rank 1's message; rank 1 killed must end it too; srun with one
#          task and no MPI plugin runs one process, with two it stops with what to run instead
#   all    both (default)
# Defaults: BUILD_DIR=<repo>/build/release SOURCE_DIR=<repo> WORK_DIR=/tmp/desplat-srun
# Debian 12: slurm-wlm 22.05, Open MPI 4.1.4, PMIx 4.2. Open MPI there joins srun only through
# PMIx (built without PMI-1/2 clients): --mpi=pmix (SRUN_MPI) is the plugin that works.
set -uo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
mode=${1:-all}
build=${2:-$repo/build/release}
source=${3:-$repo}
work=${4:-/tmp/desplat-srun}
mpi_plugin=${SRUN_MPI:-pmix}
# task/affinity (default, Slurm's usual) lets srun pin each rank to a core (--cpu-bind=cores); task/none binds
# nothing, and then the ranks' busy-waiting collectives can stall each other on a loaded machine.
task_plugin=${SRUN_TASK_PLUGIN:-task/affinity}

fails=0
pass() { echo "PASS: $*"; }
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

setup() {
  # slurm-wlm and munge for the cluster; strace, bc and python3 for the check's measurements.
  if ! command -v slurmctld > /dev/null || ! command -v munged > /dev/null || ! command -v strace > /dev/null ||
    ! command -v bc > /dev/null || ! command -v python3 > /dev/null; then
    DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge strace bc python3 > /dev/null ||
      { echo "apt-get failed"; exit 1; }
  fi
  # munge: a key (the package's postinst makes one; make one if absent), then the daemon.
  if [ ! -s /etc/munge/munge.key ]; then
    mungekey --create --keyfile /etc/munge/munge.key 2> /dev/null ||
      dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2> /dev/null
  fi
  chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
  mkdir -p /run/munge /var/log/munge /var/lib/munge
  chown munge:munge /run/munge /var/log/munge /var/lib/munge
  chmod 755 /run/munge
  if ! munge -n 2> /dev/null | unmunge > /dev/null 2>&1; then
    runuser -u munge -- /usr/sbin/munged || { echo "munged did not start"; exit 1; }
    sleep 1
  fi
  munge -n | unmunge > /dev/null || { echo "munge round trip failed"; exit 1; }

  host=$(hostname -s)
  # CPUs etc. as slurmd sees this machine (first line of slurmd -C).
  node_line=$(slurmd -C | head -1)
  node_line=${node_line/NodeName=$host/NodeName=$host NodeAddr=127.0.0.1}
  mkdir -p /etc/slurm /var/lib/slurm/slurmctld /var/lib/slurm/slurmd /var/log/slurm /run/slurm
  conf=/etc/slurm/slurm.conf
  new=$(mktemp)
  cat > "$new" << EOF
# One-node cluster for desplat's srun check (written by srun_check.sh).
ClusterName=desplat
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldPidFile=/run/slurm/slurmctld.pid
SlurmdPidFile=/run/slurm/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
SlurmctldPort=6817
SlurmdPort=6818
ProctrackType=proctrack/linuxproc
TaskPlugin=$task_plugin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=10
MinJobAge=60
$node_line State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
EOF
  restart=0
  if ! cmp -s "$new" "$conf"; then cp "$new" "$conf"; restart=1; fi
  rm -f "$new"
  # No cgroup.conf: slurmd 22.05 autodetects cgroup/v1 here; "CgroupPlugin=disabled" only exists
  # from 23.x on and makes 22.05's slurmd fail ("cannot find cgroup plugin for disabled").
  if [ $restart = 1 ]; then
    for d in slurmctld slurmd; do
      [ -f /run/slurm/$d.pid ] && kill "$(cat /run/slurm/$d.pid)" 2> /dev/null
    done
    sleep 2
  fi
  pgrep -x slurmctld > /dev/null || /usr/sbin/slurmctld || { echo "slurmctld did not start"; exit 1; }
  sleep 1
  pgrep -x slurmd > /dev/null || /usr/sbin/slurmd || { echo "slurmd did not start"; exit 1; }
  for _ in $(seq 30); do
    state=$(sinfo -h -n "$host" -o %T 2> /dev/null | head -1)
    case $state in idle | mixed | allocated) break ;; esac
    sleep 1
  done
  case $state in
  idle | mixed | allocated) pass "slurm up: node $host is $state" ;;
  *)
    scontrol update nodename="$host" state=resume 2> /dev/null
    sleep 2
    state=$(sinfo -h -n "$host" -o %T | head -1)
    [ "$state" = idle ] && pass "slurm up: node $host is $state (after resume)" ||
      { fail "slurm node $host is '$state'"; sinfo; exit 1; }
    ;;
  esac
}

# Open MPI under root with shared memory only, as the CMake tests set it (tests/CMakeLists.txt).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl=self,vader \
  OMPI_MCA_btl_vader_single_copy_mechanism=none

# The check: the equivalence test's tiny_distractors job (tests/mpi/train_ranks.sh) with 2 ranks.
check() {
  [ -x "$build/apps/desplat_train" ] && [ -x "$build/apps/desplat_synth" ] ||
    { fail "no desplat_train or desplat_synth in $build/apps (build first)"; return; }
  sinfo -h -o %T | grep -q -E 'idle|mixed' || { fail "slurm is not up (run: $0 setup)"; return; }
  # A snapshot of the binaries: every run below uses the same ones even if the build relinks them.
  mkdir -p "$work/bin"
  cp "$build/apps/desplat_train" "$build/apps/desplat_synth" "$work/bin/"
  local train=$work/bin/desplat_train synth=$work/bin/desplat_synth
  echo "source $(git -C "$source" rev-parse --short HEAD 2> /dev/null)$(git -C "$source" diff --quiet HEAD 2> /dev/null || echo ' (with local changes)'); desplat_train md5 $(md5sum < "$train" | cut -d' ' -f1)"
  echo "$(srun --version), $(mpirun --version | head -1), nice ${NICE_LEVEL:-10}, load $(cut -d' ' -f1-3 /proc/loadavg)"
  local scene=$work/scene damaged=$work/scene_damaged runs=$work/runs
  rm -rf "$runs" && mkdir -p "$runs"
  rm -rf "$scene" "$damaged"
  "$synth" --scene "$source/data/synthetic/tiny_distractors.json" --out "$scene" -q > /dev/null ||
    { fail "desplat_synth"; return; }
  local args=(--data "$scene" --preset fast --iterations 1200 --threads 1 --checkpoint-every 0
    --effects distractors --batch 2)
  # srun's tasks are slurmd's children, so a nice on srun would not reach them: nice each task.
  local bind=()
  scontrol show config | grep -q 'TaskPlugin *= *task/affinity' && bind=(--cpu-bind=cores)
  local srun_cmd=(srun -n 2 -c 1 "${bind[@]}" --mpi="$mpi_plugin" --label nice -n "${NICE_LEVEL:-10}")
  echo "srun command: ${srun_cmd[*]} desplat_train ..."
  local t0 t1 st
  # timed_run NAME LABEL CMD...: runs CMD with stdout/stderr in $runs/NAME.log/.err, prints its
  # exit status and wall seconds; returns 1 (after saying so) when it failed.
  timed_run() {
    local name=$1 label=$2
    shift 2
    t0=$(date +%s.%N)
    "$@" > "$runs/$name.log" 2> "$runs/$name.err"
    st=$?
    t1=$(date +%s.%N)
    echo "$label: exit $st, $(echo "$t1 - $t0" | bc) s"
    [ $st -eq 0 ] || { fail "$label exited $st:"; tail -20 "$runs/$name.err"; return 1; }
  }

  # 1. srun, plain
  timed_run srun_a "srun run a" "${srun_cmd[@]}" "$train" "${args[@]}" --out "$runs/srun_a" || return
  # 2. srun again, each rank under strace (file-creating calls only) to see who writes the output
  timed_run srun_b "srun run b (strace)" "${srun_cmd[@]}" bash -c 'exec strace -f --seccomp-bpf -qq \
      -o "$0/strace.rank$SLURM_PROCID" \
      -e trace=open,openat,creat,rename,renameat,renameat2,mkdir,mkdirat,unlink,unlinkat,truncate "$@"' \
    "$runs" "$train" "${args[@]}" --out "$runs/srun_b" || return
  # 3. mpirun, same arguments
  timed_run mpirun "mpirun run" nice -n "${NICE_LEVEL:-10}" mpirun -np 2 --oversubscribe "$train" "${args[@]}" \
    --out "$runs/mpirun" || return

  local m r
  for r in srun_a srun_b mpirun; do
    m=$(md5sum < "$runs/$r/point_cloud.ply" | cut -d' ' -f1)
    echo "$r: point_cloud.ply md5 $m; $(python3 -c '
import json, sys
m = json.load(open(sys.argv[1]))
print("test PSNR %.6f dB, SSIM %.6f, %d static Gaussians, step %d, ranks %d (%s)" % (m["mean_psnr"], m["mean_ssim"],
      m["gaussians"], m["step"], m["ranks"]["count"], m["ranks"]["communicator"]))' "$runs/$r/metrics.json")"
    grep -h '^0: done:' "$runs/$r.log" | sed "s/^/  $r: /" || grep -h '^done:' "$runs/$r.log" | sed "s/^/  $r: /"
  done
  local a b c
  a=$(md5sum < "$runs/srun_a/point_cloud.ply") b=$(md5sum < "$runs/srun_b/point_cloud.ply")
  c=$(md5sum < "$runs/mpirun/point_cloud.ply")
  [ "$a" = "$b" ] && pass "srun reruns: point_cloud.ply bit-identical" || fail "srun reruns differ"
  [ "$a" = "$c" ] && pass "srun and mpirun: point_cloud.ply bit-identical" || fail "srun and mpirun point_cloud.ply differ"
  # metrics: test PSNR, SSIM, Gaussian count, step, rank count equal
  if python3 - "$runs/srun_a/metrics.json" "$runs/mpirun/metrics.json" << 'EOF'; then
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
keys = ["mean_psnr", "mean_ssim", "gaussians", "step"]
bad = [k for k in keys if a[k] != b[k]] + (["ranks.count"] if a["ranks"]["count"] != b["ranks"]["count"] or a["ranks"]["count"] != 2 else [])
if bad: print("differ:", bad); sys.exit(1)
EOF
    pass "srun and mpirun: metrics.json test PSNR, SSIM, Gaussian count, step equal; 2 ranks"
  else fail "srun and mpirun metrics differ"; fi
  grep -q '^0: done:' "$runs/srun_a.log" && grep -q '"communicator": "MPI' "$runs/srun_a/metrics.json" &&
    pass "srun job ran as 2 MPI ranks (metrics.json ranks.communicator)" ||
    { fail "srun job not 2 MPI ranks"; grep -A3 '"ranks"' "$runs/srun_a/metrics.json"; }

  # Only rank 0 prints: with --label every line carries its task id.
  local r1
  r1=$(cat "$runs/srun_a.log" "$runs/srun_a.err" "$runs/srun_b.log" | grep -c -v '^ *0: ' || true)
  [ "$r1" -eq 0 ] && [ "$(grep -c '^ *0: ' "$runs/srun_a.log")" -gt 0 ] &&
    pass "only rank 0 prints progress ($(grep -c '^ *0: ' "$runs/srun_a.log") lines from task 0, none from task 1)" ||
    { fail "lines not from rank 0: $r1"; grep -v '^ *0: ' "$runs/srun_a.log" "$runs/srun_a.err" | head; }
  # The same messages as mpirun's, progress aside: under mpirun a rank's stdout is a pty (Open
  # MPI's default), so desplat draws its \r progress bar; under srun it is a pipe, so desplat logs
  # a line every 100 steps. Compare everything else, timings and folder names masked.
  norm() { tr '\r' '\n' < "$1" | sed -E 's/^ *0: //' | grep -v -E '^(\[[#.]*\])? *[0-9]+/[0-9]+ ' |
    sed -E "s|$runs/[a-z_]+|OUT|g; s/ in [0-9]+m[0-9]+s/ in T/" | grep .; }
  if diff <(norm "$runs/srun_a.log") <(norm "$runs/mpirun.log") > "$runs/messages.diff"; then
    pass "srun and mpirun print the same messages besides progress ($(norm "$runs/mpirun.log" | wc -l) lines)"
  else fail "srun and mpirun messages differ:"; cat "$runs/messages.diff"; fi

  # Output written once: no rank but 0 creates, writes, renames or removes anything in the folder.
  local out=$runs/srun_b
  writes() { grep -E "\"$out[/\"]" "$1" | grep -E 'O_WRONLY|O_RDWR|O_CREAT|creat\(|rename|mkdir|unlink|truncate' | grep -v ' = -1 ' ; }
  local w0 w1 ply
  w0=$(writes "$runs/strace.rank0" | wc -l) w1=$(writes "$runs/strace.rank1" | wc -l)
  ply=$(writes "$runs/strace.rank0" | grep -c -E 'point_cloud\.ply[^/]*", O_' || true)
  echo "file-changing calls in $out: rank 0 $w0, rank 1 $w1; rank 0 opens for writing point_cloud.ply* $ply time(s)"
  writes "$runs/strace.rank0" | sed -E 's/^[0-9]+ +//; s/, 0[0-7]+\)/)/' | sed "s|$out|OUT|g" | sort | uniq -c | sort -rn |
    head -8 | sed 's/^/  rank 0: /'
  [ "$w1" -eq 0 ] && [ "$w0" -gt 0 ] && pass "the output folder is written by rank 0 only" ||
    { fail "rank 1 changed the output folder $w1 times"; writes "$runs/strace.rank1" | head; }
  [ "$ply" -eq 1 ] && pass "point_cloud.ply written once" || fail "point_cloud.ply opened for writing $ply times"

  # A photo only rank 1 holds (training view 1 = 0002.png, view i is rank i mod 2's) is damaged.
  cp -r "$scene" "$damaged"
  head -c 100 "$scene/images/0002.png" > "$damaged/images/0002.png"
  t0=$(date +%s.%N)
  timeout 120 "${srun_cmd[@]}" "$train" --data "$damaged" --iterations 100 --threads 1 --out "$runs/damaged" \
    > "$runs/damaged.log" 2> "$runs/damaged.err"
  st=$?
  t1=$(date +%s.%N)
  echo "damaged photo on rank 1: srun exit $st after $(echo "$t1 - $t0" | bc) s; its stderr:"
  sed 's/^/  | /' "$runs/damaged.err" | head -30
  [ $st -ne 0 ] && [ $st -ne 124 ] && pass "damaged photo: the srun job ended (exit $st, not the timeout)" ||
    fail "damaged photo: exit status $st (124: the job hung 120 s)"
  grep -q "rank 1: desplat_train: error: .*0002.png" "$runs/damaged.err" &&
    pass "damaged photo: the message names rank 1 and 0002.png" || fail "no 'rank 1: desplat_train: error: ...0002.png'"
  grep -q "rank 0: desplat_train: error" "$runs/damaged.err" && fail "rank 0 reported an error of its own" ||
    pass "damaged photo: rank 0 reported no error of its own"
  [ ! -e "$runs/damaged/checkpoint.ckpt" ] && [ ! -e "$runs/damaged/point_cloud.ply" ] &&
    pass "damaged photo: no model written" || fail "damaged photo: a model was written"

  # srun with one task and no MPI plugin: one process, MPI never initialized.
  srun -n 1 --mpi=none nice -n "${NICE_LEVEL:-10}" "$train" --data "$scene" --iterations 50 --threads 1 \
    --out "$runs/one_task" > "$runs/one_task.log" 2> "$runs/one_task.err"
  st=$?
  [ $st -eq 0 ] && grep -q '"communicator": "single process"' "$runs/one_task/metrics.json" &&
    pass "srun -n 1 without an MPI plugin: one process" ||
    { fail "srun -n 1 --mpi=none: exit $st"; tail -5 "$runs/one_task.err"; }
  # Two tasks and no MPI plugin: MPI_Init cannot work; each task says what to run instead.
  timeout 120 srun -n 2 --mpi=none "$train" --data "$scene" --iterations 50 --threads 1 --out "$runs/no_plugin" \
    > "$runs/no_plugin.log" 2> "$runs/no_plugin.err"
  st=$?
  [ $st -ne 0 ] && [ $st -ne 124 ] && grep -q "desplat_train: error: started by srun as 2 tasks without an MPI plugin .*srun --mpi=pmix" "$runs/no_plugin.err" &&
    [ ! -e "$runs/no_plugin" ] && pass "srun -n 2 without an MPI plugin: exit $st, 'run srun --mpi=pmix', nothing written" ||
    { fail "srun -n 2 --mpi=none: exit $st"; head -5 "$runs/no_plugin.err"; }

  # Rank 1 killed mid-run (tests/mpi/train_ranks.sh's kill case): the srun job must end on its own,
  # and its last checkpoint must resume in one process.
  local job victim pid step
  "${srun_cmd[@]}" "$train" --data "$scene" --iterations 1000000 --threads 1 --checkpoint-every 50 \
    --effects distractors --out "$runs/kill" > "$runs/kill.log" 2> "$runs/kill.err" &
  job=$!
  for _ in $(seq 600); do [ -f "$runs/kill/checkpoint.ckpt" ] && break; sleep 0.2; done
  victim=""
  for pid in $(pgrep -f "$runs/kill" || true); do
    tr '\0' '\n' < /proc/$pid/environ 2> /dev/null | grep -qx 'PMIX_RANK=1' && victim=$pid
  done
  if [ ! -f "$runs/kill/checkpoint.ckpt" ] || [ -z "$victim" ]; then
    fail "kill: no checkpoint within 120 s or rank 1 not found"; kill "$job" 2> /dev/null; wait "$job"
  else
    t0=$(date +%s.%N)
    kill -9 "$victim"
    for _ in $(seq 300); do kill -0 "$job" 2> /dev/null || break; sleep 0.2; done
    t1=$(date +%s.%N)
    if kill -0 "$job" 2> /dev/null; then
      fail "kill: the srun job still runs 60 s after rank 1 died"; kill -9 "$job"; wait "$job"
    else
      st=0; wait "$job" || st=$?
      echo "rank 1 killed: srun exit $st after $(echo "$t1 - $t0" | bc) s; its stderr:"
      sed 's/^/  | /' "$runs/kill.err"
      [ $st -ne 0 ] && pass "kill: the srun job ended on its own (exit $st)" || fail "kill: srun reported success"
      step=$(grep -a -o '"step":[0-9]*' "$runs/kill/checkpoint.ckpt" | head -1 | cut -d: -f2)
      "$train" --data "$scene" --out "$runs/kill" --resume --iterations $((step + 20)) > "$runs/resume.log" 2>&1
      grep -q "resumed from .* at step $step" "$runs/resume.log" && grep -q '"step": '$((step + 20)) "$runs/kill/metrics.json" &&
        pass "kill: the checkpoint at step $step resumed in one process" || fail "kill: resume failed"
    fi
  fi

  sleep 1
  [ -z "$(squeue -h)" ] && pass "no job left in the queue" || { fail "jobs left:"; squeue; }
}

case $mode in
setup) setup ;;
check) check ;;
all) setup && check ;;
*) echo "usage: $0 [setup|check|all] [BUILD_DIR] [SOURCE_DIR] [WORK_DIR]"; exit 2 ;;
esac
echo
if [ $fails -eq 0 ]; then echo "srun check: all PASS"; else echo "srun check: $fails FAIL"; fi
[ $fails -eq 0 ]
