// Tile geometry shared by binning and the two tile passes.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

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

// The 8-column halves of each tile row, within the box's halves, that hold a pixel centre
// where one Gaussian's α can reach 1/255: the row's chord of the ellipse
// σ(dx, dy) = ½a·dx² + b·dx·dy + ½c·dy² ≤ s, with dx = mx − px, dy = my − py as the pixel
// loops compute them and s = ln(255·o) + 0.01 (opacity_extent_sigmas' margin). The box is
// the ellipse's bounding rectangle, so a tilted or thin ellipse leaves one half of many
// rows empty, and the loops skip it. Exact: a skipped half holds no pixel the loops would
// blend (tests/test_stage_math.cpp checks it against the loops' own float σ). The shape is
// built once per Gaussian (chord_shape, in double, with s widened by a bound on the loops'
// float error in σ: a few units of roundoff of its largest term within the box) and stored
// with the projection (TileSplat::chord); each tile entry then places it (RowChords) and
// its rows cost one vector pass of float square roots (row_halves). Rows of a box within
// one half gain only when the chord misses them whole.
constexpr int kChordFloats = 4;  // slope, curvature, reach, pad; reach NaN: no chord

// For row dy the chord is px ∈ mx + slope·dy ± (√(curvature·dy² + reach) + pad), with
// slope = b/a, curvature = (b² − ac)/a², reach = 2·level/a. rx, ry: the blend box [px].
inline void chord_shape(float a, float b, float c, float opacity, int rx, int ry, float* shape) {
  shape[0] = shape[1] = shape[3] = 0.0f;
  shape[2] = NAN;
  if (!(a > 0.0f)) return;
  const double ad = a, bd = b, cd = c, px = double(rx) + 1.0, py = double(ry) + 1.0;
  const double largest = 0.5 * ad * px * px + std::abs(bd) * px * py + 0.5 * cd * py * py;
  const double level = std::log(255.0 * double(opacity)) + 0.01 + 2e-6 * largest;
  const double reach = 2.0 * level / ad;
  const float curvature = float((bd * bd - ad * cd) / (ad * ad));
  if (!(level > 0.0) || !std::isfinite(reach) || !std::isfinite(curvature)) return;
  shape[0] = float(bd / ad);
  shape[1] = curvature;
  shape[2] = float(reach * (1.0 + 1e-5));  // the float evaluation cancels up to ~1e-7·reach
  shape[3] = float(0.01 + 1e-5 * std::sqrt(reach));
}

// One Gaussian's chord shape placed in one tile: centre mx, tile column x0, box halves [h0, h1].
class RowChords {
 public:
  RowChords(const float* shape, float mx, int x0, int h0, int h1)
      : h0_(h0), h1_(h1), used_(h0 <= h1 && shape[2] > 0.0f) {
    if (!used_) return;
    slope_ = shape[0], curvature_ = shape[1], reach_ = shape[2], pad_ = shape[3];
    centre_ = float(double(mx) - x0 - 0.5);  // column coordinate of the centre
  }
  // The halves [rh0[r], rh1[r]] of every row r of a tile starting at pixel row y0, with
  // dy = my − (y0 + r + 0.5) as the loops compute it (rh0[r] > rh1[r]: none). All kTileSize
  // rows at once, branch-free, so the row loop reads a table instead of running a scalar
  // square root and a chain of compares per row (rows the box misses are filled too).
  [[gnu::always_inline]] void row_halves(float my, int y0, int32_t* rh0, int32_t* rh1) const {
    if (!used_) {
      std::fill(rh0, rh0 + kTileSize, h0_);
      std::fill(rh1, rh1 + kTileSize, h1_);
      return;
    }
#pragma omp simd
    for (int r = 0; r < kTileSize; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const float t = curvature_ * dy * dy + reach_;
      // t < 0: the row misses the ellipse (its square root is NaN, and every compare
      // below with it is false too).
      const float half_width = std::sqrt(t) + pad_, mid = centre_ + slope_ * dy;
      // Columns hold centres at 0, 1, …: the chord's first and last column.
      const float lo = std::ceil(mid - half_width), hi = std::floor(mid + half_width);
      const int32_t chord = int32_t(t >= 0.0f) & int32_t(lo <= hi);
      const int32_t first = chord & int32_t(lo <= float(kHalfTile - 1)) & int32_t(hi >= 0.0f);
      const int32_t second = chord & int32_t(lo <= float(kTileSize - 1)) & int32_t(hi >= float(kHalfTile));
      rh0[r] = std::max(h0_, 1 - first);
      rh1[r] = std::min(h1_, second);
    }
  }

 private:
  int h0_, h1_;
  bool used_;
  float slope_ = 0, curvature_ = 0, reach_ = 0, centre_ = 0, pad_ = 0;
};

inline int thread_count(const RasterSettings& s) { return s.num_threads > 0 ? s.num_threads : omp_get_max_threads(); }

}  // namespace desplat::raster
