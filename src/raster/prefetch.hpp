// Software prefetch for the per-Gaussian loops (projection, the backward's chain rule). They
// walk the SH colour rows, 48 floats (three cache lines) per Gaussian, tens of thousands of
// them per step; without a hint the loads of each row stalled (perf annotate on bench_raster's
// 135×240 trained fox) although the walk is sequential. A hint changes no result.
#pragma once

namespace desplat::raster {

// How many Gaussians ahead the loops ask for a row. The projection runs in blocks of 16
// (gaussian_lanes.hpp), so the distance covers the next block and a half; it matters in
// training, where Adam has evicted the rows from the cache by the next step, and not on small
// models whose rows stay cached (docs/BENCHMARKS.md, speed).
constexpr int kRowPrefetchDistance = 24;

// Asks for the cache lines of floats [row, row + count) to be read (or written) soon.
inline void prefetch_row_for_read(const float* row, int count) {
  const char* bytes = reinterpret_cast<const char*>(row);
  for (int b = 0; b < count * int(sizeof(float)); b += 64) __builtin_prefetch(bytes + b, 0);
}
inline void prefetch_row_for_write(float* row, int count) {
  char* bytes = reinterpret_cast<char*>(row);
  for (int b = 0; b < count * int(sizeof(float)); b += 64) __builtin_prefetch(bytes + b, 1);
}

}  // namespace desplat::raster
