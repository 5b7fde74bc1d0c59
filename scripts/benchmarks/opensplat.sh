#!/bin/bash
# BENCHMARKS.md, "Speed", "Against OpenSplat": desplat against OpenSplat
# (github.com/WebODM/OpenSplat), the CPU Gaussian-splatting trainer, in one run on one machine. Both train on the fox
# ($FOX: sparse/ and images/, only read) at 1/4 size throughout, for $ITERATIONS steps, with
# 0027.jpg held out and scored by each tool's own PSNR. Each is measured by /usr/bin/time -v
# (wall time, peak RSS). Prints a markdown table and writes it to $WORK/opensplat/summary.md.
# Run it alone on the machine; the first run installs packages (apt-get, as root) and builds
# OpenSplat (CPU only, against Debian's libtorch), later runs reuse that build.
#   ITERATIONS       training steps of each tool (default 2000)
#   OPENSPLAT_SRC    OpenSplat's source: a source tree, a work tree or a bare git directory (its
#                    HEAD is exported); default: git clone https://github.com/WebODM/OpenSplat
#   OPENSPLAT_BUILD  folder for the patched source copy, the build and the commit it was built
#                    from (default $WORK/opensplat/build); an existing build there is reused
#   KERNEL_ISA       desplat's pixel loops (kernel_isa: auto, avx2, …; default auto). To run
#                    both as on an AVX2-only CPU from an AVX-512 one: APPS from an x86-64-v3
#                    build (scripts/benchmarks/avx2.sh), KERNEL_ISA=avx2 and
#                    ATEN_CPU_CAPABILITY=avx2 (libtorch's kernels; OpenSplat's own code is
#                    built without -march, for any x86-64)
source "$(dirname "$0")/lib.sh"
ITERATIONS=${ITERATIONS:-2000}
KERNEL_ISA=${KERNEL_ISA:-auto}
VAL=0027.jpg
THREADS=2
R=$WORK/opensplat
OSB=$(realpath -m "${OPENSPLAT_BUILD:-$R/build}")
BIN=$OSB/build/opensplat
mkdir -p "$R" "$OSB"

# Packages: libtorch (1.13.1 on Debian 12) and the build tools. OpenSplat vendors its other
# dependencies (nlohmann/json, glm, cxxopts, nanoflann, miniz, zstd, spz) in vendor/.
missing=()
for p in libtorch-dev libopencv-dev cmake ninja-build g++ git; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=(); [ "$(id -u)" = 0 ] || sudo=(sudo)
  "${sudo[@]}" apt-get update
  DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y --no-install-recommends "${missing[@]}"
fi

# Source: a fresh copy in $OSB/src, never the tree OPENSPLAT_SRC names (the patches below edit it).
if [ ! -x "$BIN" ]; then
  src=${OPENSPLAT_SRC:-}
  if [ -z "$src" ]; then
    src=$OSB/clone
    [ -d "$src" ] || git clone --depth 1 https://github.com/WebODM/OpenSplat "$src" ||
      { echo "cannot clone OpenSplat: set OPENSPLAT_SRC to its source or a git dir of it" >&2; exit 1; }
  fi
  rm -rf "$OSB/src" && mkdir -p "$OSB/src"
  if [ -e "$src/.git" ] || { [ -f "$src/HEAD" ] && [ -d "$src/objects" ]; }; then  # work tree or git dir
    git -C "$src" rev-parse HEAD > "$OSB/commit"
    git -C "$src" archive HEAD | tar -x -C "$OSB/src"
  else
    cp -a "$src/." "$OSB/src/" && echo "unknown (copied from $src)" > "$OSB/commit"
  fi
  # Patch for torch < 2. torch 1.13's Optimizer::zero_grad() takes no argument; OpenSplat calls
  # zero_grad(true) (set_to_none) after each Adam step. Under torch < 2 the patch resets each
  # parameter's gradient to undefined by hand, which is what zero_grad(true) does in torch 2;
  # with torch >= 2 the original call stays. This is the only change the build needs.
  reset='for (auto \&group : opt->param_groups()) for (auto \&p : group.params()) p.mutable_grad().reset();'
  sed -i "s|^\( *\)opt->zero_grad(true);|#if TORCH_VERSION_MAJOR < 2\n\1$reset\n#else\n&\n#endif|" "$OSB/src/model.cpp"
  grep -q 'p.mutable_grad().reset()' "$OSB/src/model.cpp" || { echo "zero_grad patch did not apply" >&2; exit 1; }
  start=$(date +%s)
  cmake -S "$OSB/src" -B "$OSB/build" -G Ninja -DGPU_RUNTIME=CPU -DCMAKE_BUILD_TYPE=Release > "$OSB/cmake.log" 2>&1
  ninja -C "$OSB/build" -j "$(nproc)" opensplat > "$OSB/build.log" || { tail -30 "$OSB/build.log" >&2; exit 1; }
  echo "OpenSplat built in $(($(date +%s) - start)) s"
fi
commit=$(cat "$OSB/commit")
torch=$(dpkg-query -W -f='${Version}' libtorch-dev)

# Two cores each: OMP_NUM_THREADS sizes libtorch's pool, but OpenSplat's CPU rasterizer starts
# one thread per core (std::thread::hardware_concurrency), so on a machine with more cores both
# tools are pinned to the first $THREADS.
pin=(); [ "$(nproc)" -gt $THREADS ] && pin=(taskset -c "0-$((THREADS - 1))")
export OMP_NUM_THREADS=$THREADS

# desplat: --split lists with a test list of one name trains on every other view.
echo "$VAL" > "$R/test_list.txt"
echo "desplat: $ITERATIONS steps"
"${pin[@]}" /usr/bin/time -v -o "$R/desplat.time" "$APPS/desplat_train" --data "$FOX" --out "$R/desplat" \
  --overwrite --static-only --config "{\"num_downscales\": 0, \"kernel_isa\": \"$KERNEL_ISA\"}" --downscale 4 --iterations "$ITERATIONS" \
  --threads $THREADS --split lists --test-list "$R/test_list.txt" --checkpoint-every 0 > "$R/desplat.log" 2>&1 ||
  { tail -20 "$R/desplat.log" >&2; exit 1; }

# OpenSplat: --val holds one view out, --val-image names it; after the last step it prints
# "<path> validation PSNR: <dB>" for that view. It writes only its -o PLY and cameras.json
# beside it, so it reads the fox in place. --num-downscales defaults to 0 (1/4 size throughout).
echo "OpenSplat: $ITERATIONS steps"
rm -rf "$R/opensplat" && mkdir -p "$R/opensplat"
"${pin[@]}" /usr/bin/time -v -o "$R/opensplat.time" "$BIN" "$FOX" -o "$R/opensplat/splat.ply" --cpu \
  --val --val-image "$VAL" --downscale-factor 4 --num-iters "$ITERATIONS" > "$R/opensplat.log" 2>&1 ||
  { tail -20 "$R/opensplat.log" >&2; exit 1; }

python3 - "$R" "$VAL" "$ITERATIONS" "$commit" "$torch" "$(git -C "$ROOT" rev-parse --short HEAD)" "$(machine)" \
  "$KERNEL_ISA" "${ATEN_CPU_CAPABILITY:-default}" <<'PY'
import json, re, sys
r, val, iters, commit, torch, desplat_commit, machine, isa, aten = sys.argv[1:]

def usage(path):  # wall seconds and peak RSS [MB] from /usr/bin/time -v
    t = open(path).read()
    clock = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", t).group(1).split(":")
    wall = sum(float(x) * 60 ** i for i, x in enumerate(reversed(clock)))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    return wall, rss

m = json.load(open(f"{r}/desplat/metrics.json"))
names = [v["name"] for v in m["views"]]
assert names == [val], f"desplat scored {names}, not [{val}]"
log = open(f"{r}/opensplat.log").read()
found = re.findall(r"(\S+) validation PSNR: (\S+)", log)
assert len(found) == 1 and found[0][0].endswith("/" + val), f"OpenSplat validation lines: {found}"
with open(f"{r}/opensplat/splat.ply", "rb") as f:  # Gaussians: the PLY header's vertex count
    header = f.read(4096).split(b"end_header")[0].decode("ascii", "replace")
os_gaussians = int(re.search(r"element vertex (\d+)", header).group(1))
# Training size: desplat's log line "... views at WxH", OpenSplat's cameras.json for the view.
size = re.search(r"views at (\d+x\d+)", open(f"{r}/desplat.log").read()).group(1)
cam = [c for c in json.load(open(f"{r}/opensplat/cameras.json")) if c["img_name"] == val][0]
os_size = f"{cam['width']}x{cam['height']}"
size = size if size == os_size else f"{size} (desplat), {os_size} (OpenSplat)"

rows = [("desplat", *usage(f"{r}/desplat.time"), m["mean_psnr"], m["gaussians"]),
        ("OpenSplat", *usage(f"{r}/opensplat.time"), float(found[0][1]), os_gaussians)]
out = [f"Fox, 1/4 size ({size}), {iters} steps, {val} held out; desplat {desplat_commit} "
       f"(--static-only, --threads 2, kernel_isa {isa}: {m['median_step_seconds_full_resolution']['kernel_isa']}), "
       f"OpenSplat {commit[:12]} (--cpu, libtorch {torch}, ATEN_CPU_CAPABILITY {aten}).", "",
       "| tool | wall | peak RSS | held-out PSNR | Gaussians |", "|---|---|---|---|---|"]
out += [f"| {n} | {w:.1f} s | {rss:.0f} MB | {p:.2f} dB | {g:,} |" for n, w, rss, p, g in rows]
out += ["", f"OpenSplat / desplat wall time: {rows[1][1] / rows[0][1]:.2f}x", "", f"machine: {machine}"]
text = "\n".join(out) + "\n"
open(f"{r}/summary.md", "w").write(text)
print(text, end="")
PY
