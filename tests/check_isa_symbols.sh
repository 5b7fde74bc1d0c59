#!/usr/bin/env bash
# Checks that an object file compiled for one instruction set (src/raster/tile_kernels_<isa>.cpp)
# exports nothing but its own namespace desplat::raster::<isa>. An exported inline helper or
# template compiled with AVX-512 could be the copy the linker keeps for every other file, and
# a CPU without AVX-512 would then fault outside the dispatched path.
# Usage: check_isa_symbols.sh OBJECT ISA   (exit 1 and the offending symbols on failure)
set -euo pipefail
object=$1 isa=$2
foreign=$(nm -C --defined-only --extern-only "$object" | cut -c20- | grep -v "^desplat::raster::${isa}::" || true)
if [ -n "$foreign" ]; then
  echo "$object (compiled for $isa) exports symbols outside desplat::raster::${isa}:"
  echo "$foreign"
  exit 1
fi
echo "$object exports only desplat::raster::${isa}::"
