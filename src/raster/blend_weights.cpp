// Per-Gaussian blend weight Σ_pixels αᵢTᵢ of a finished forward pass: a statistic for density
// control, off the training hot path (it walks the tiles once more, one thread).
#include <algorithm>
#include <stdexcept>

#include "desplat/raster/raster.hpp"
#include "raster/fast_exp.hpp"
#include "raster/stage_math.hpp"
#include "raster/tiles.hpp"

namespace desplat {
using namespace raster;

std::vector<double> blend_weights(const RasterOutput& out) {
  const size_t n = out.opacity.size();
  if (out.tile_offsets.empty() || out.width <= 0 || out.height <= 0)
    throw std::invalid_argument("blend_weights: the render has no tiles (call rasterize_forward first)");
  std::vector<double> weight(n, 0.0);
  const int tiles_x = (out.width + kTileSize - 1) / kTileSize;
  const int tiles = int(out.tile_offsets.size()) - 1;
  std::vector<float> T(kTileSize * kTileSize);
  std::vector<uint8_t> active(kTileSize * kTileSize);
  for (int tile = 0; tile < tiles; ++tile) {
    const int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
    const int cols = std::min(kTileSize, out.width - x0), rows = std::min(kTileSize, out.height - y0);
    std::fill(T.begin(), T.end(), 1.0f);
    std::fill(active.begin(), active.end(), uint8_t(1));
    // The same α, the same order and the same stopping rule as the forward's pixel loop
    // (tile_kernels.inl, blend_tile), so Σ over Gaussians of a pixel's weights is its alpha.
    for (int e = out.tile_offsets[tile]; e < out.tile_offsets[tile + 1]; ++e) {
      const int32_t g = out.tile_entries[e];
      const float mx = out.means2d[2 * g], my = out.means2d[2 * g + 1];
      const float a = out.conics[3 * g], b = out.conics[3 * g + 1], c = out.conics[3 * g + 2];
      const float o = out.opacity[g];
      int r0, r1;
      box_rows_in_tile(my, out.blend_radii[2 * g + 1], y0, rows, r0, r1);
      for (int r = r0; r <= r1; ++r) {
        const float dy = my - (y0 + r + 0.5f);
        for (int col = 0; col < cols; ++col) {
          const int j = r * kTileSize + col;
          if (!active[j]) continue;
          const float dx = mx - (x0 + col + 0.5f);
          const float sigma = gaussian_sigma(a, b, c, dx, dy);
          const float alpha = clamp_alpha(o * fast_exp_nonpositive(-sigma));
          if (!(sigma >= 0.0f) || !(alpha >= kAlphaMin)) continue;
          const float next_t = T[j] * (1.0f - alpha);
          if (next_t <= kTransmittanceMin) {  // the forward stops here without blending
            active[j] = 0;
            continue;
          }
          weight[size_t(g)] += double(alpha * T[j]);
          T[j] = next_t;
        }
      }
    }
  }
  return weight;
}

}  // namespace desplat
