// Total variation of the distractor alpha (docs/METHOD.md §4).
#include "desplat/train/mask_coherence.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace desplat {

double mask_total_variation(std::span<const float> alpha, int width, int height, float lambda,
                            std::span<float> d_alpha, std::span<const float> keep) {
  const size_t pixels = size_t(std::max(width, 0)) * size_t(std::max(height, 0));
  if (width < 0 || height < 0 || alpha.size() != pixels || d_alpha.size() != pixels ||
      (!keep.empty() && keep.size() != pixels))
    throw std::invalid_argument("mask_total_variation: sizes disagree");
  if (lambda == 0 || pixels == 0) return 0;
  double kept = double(pixels);
  if (!keep.empty()) {
    kept = 0;
    for (float k : keep) kept += k > 0;
    if (kept == 0) return 0;
  }
  const float g = lambda / float(kept);
  double sum = 0;
  auto pair = [&](size_t p, size_t q) {
    if (!keep.empty() && (keep[p] == 0 || keep[q] == 0)) return;
    const float diff = alpha[p] - alpha[q];
    sum += std::abs(double(diff));
    const float s = diff > 0 ? g : diff < 0 ? -g : 0.0f;
    d_alpha[p] += s;
    d_alpha[q] -= s;
  };
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t p = size_t(y) * size_t(width) + size_t(x);
      if (x + 1 < width) pair(p, p + 1);
      if (y + 1 < height) pair(p, p + size_t(width));
    }
  return double(lambda) * sum / kept;
}

}  // namespace desplat
