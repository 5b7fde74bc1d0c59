// Tile geometry shared by binning and the two tile passes.
#pragma once

#include <algorithm>
#include <cmath>

#include <omp.h>

#include "desplat/raster/raster.hpp"

namespace desplat::raster {

struct TileGrid {
  int tiles_x = 0, tiles_y = 0;
  TileGrid(int width, int height)
      : tiles_x((width + kTileSize - 1) / kTileSize), tiles_y((height + kTileSize - 1) / kTileSize) {}
  int count() const { return tiles_x * tiles_y; }
};

// Tiles [x0, x1) × [y0, y1) overlapped by a Gaussian's box (gsplat's isect_tiles).
struct TileRect {
  int x0, y0, x1, y1;
  int area() const { return std::max(0, x1 - x0) * std::max(0, y1 - y0); }
};

inline TileRect tile_rect(const TileGrid& grid, float mx, float my, int rx, int ry) {
  const float t = static_cast<float>(kTileSize);
  auto clampi = [](float v, int hi) { return static_cast<int>(std::clamp(v, 0.0f, float(hi))); };
  return {clampi(std::floor((mx - rx) / t), grid.tiles_x), clampi(std::floor((my - ry) / t), grid.tiles_y),
          clampi(std::ceil((mx + rx) / t), grid.tiles_x), clampi(std::ceil((my + ry) / t), grid.tiles_y)};
}

// Rows [r0, r1] of a tile starting at pixel row y0 whose centers lie within ry of my.
// Pixels outside the 3.33σ box have α < 1/255 (σ ≥ 0.5·3.33² ⇒ 0.999·e^−σ < 1/255),
// so skipping them is exact.
inline void box_rows_in_tile(float my, int ry, int y0, int rows, int& r0, int& r1) {
  r0 = std::max(0, static_cast<int>(std::floor(my - ry - 0.5f)) - y0);
  r1 = std::min(rows - 1, static_cast<int>(std::ceil(my + ry - 0.5f)) - y0);
}

// The 8-column halves [h0, h1] of a tile starting at pixel column x0 (cols wide) that hold a
// pixel center within rx of mx; h0 > h1 when none does. Same exactness argument as the
// rows: a Gaussian contributes nothing outside its box, so the pixel loops skip a half
// the box misses (one 8-lane AVX2 vector per row of a half).
constexpr int kHalfTile = kTileSize / 2;
inline void box_halves_in_tile(float mx, int rx, int x0, int cols, int& h0, int& h1) {
  int c0, c1;
  box_rows_in_tile(mx, rx, x0, cols, c0, c1);
  h0 = c0 / kHalfTile;
  h1 = c1 < c0 ? h0 - 1 : c1 / kHalfTile;
}

inline int thread_count(const RasterSettings& s) {
  return s.num_threads > 0 ? s.num_threads : omp_get_max_threads();
}

}  // namespace desplat::raster
