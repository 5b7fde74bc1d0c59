#!/bin/bash
# The fox with a different exposure and white balance in every photo (scene fox_expo of
# docs/BENCHMARKS.md): each photo, test views included, times 2^u (u uniform in [-1, 1]) times a
# per-channel factor 1 ± 10 %, clamped to [0, 1], saved as JPEG quality 95; the COLMAP model is
# the fox's. Writes OUT/images, OUT/sparse and OUT/gains.txt. Needs python3 and oiiotool.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
out="${1:-$root/out/fox_expo}"
src="$root/../shared/data/fox"
mkdir -p "$out/images"
cp -r "$src/sparse" "$out/"
python3 - "$src/images" "$out" <<'PY'
import os, random, subprocess, sys
src, out = sys.argv[1], sys.argv[2]
random.seed(15)
lines = []
for name in sorted(os.listdir(src)):
    g = 2 ** random.uniform(-1, 1)
    gains = [g * (1 + random.uniform(-0.1, 0.1)) for _ in range(3)]
    subprocess.run(["oiiotool", os.path.join(src, name), "--mulc", ",".join("%.4f" % x for x in gains),
                    "--clamp:min=0:max=1", "--attrib", "Compression", "jpeg:95",
                    "-o", os.path.join(out, "images", name)], check=True)
    lines.append(name + " " + " ".join("%.4f" % x for x in gains))
open(os.path.join(out, "gains.txt"), "w").write("\n".join(lines) + "\n")
PY
