// Total variation of the distractor alpha (docs/METHOD.md §4).
#include "desplat/train/mask_coherence.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace desplat {

namespace {
// The pixels a mean runs over: all of them, or the ones the user's mask keeps.
double kept_pixels(std::span<const float> keep, size_t pixels) {
  if (keep.empty()) return double(pixels);
  return double(std::count_if(keep.begin(), keep.end(), [](float k) { return k > 0; }));
}
}  // namespace

double mask_total_variation(std::span<const float> alpha, int width, int height, float lambda, std::span<float> d_alpha,
                            std::span<const float> keep) {
  const size_t pixels = size_t(std::max(width, 0)) * size_t(std::max(height, 0));
  if (width < 0 || height < 0 || alpha.size() != pixels || d_alpha.size() != pixels ||
      (!keep.empty() && keep.size() != pixels))
    throw std::invalid_argument("mask_total_variation: sizes disagree");
  if (lambda == 0 || pixels == 0) return 0;
  const double kept = kept_pixels(keep, pixels);
  if (kept == 0) return 0;
  const float g = lambda / float(kept);
  // Each pair of neighbours (p, q) adds sign(α_p − α_q)·g to p's gradient and subtracts it
  // from q's, unless the user's mask drops either pixel.
  auto counted = [&](size_t p, size_t q) { return keep.empty() || (keep[p] != 0 && keep[q] != 0); };
  auto step = [&](size_t p, size_t q) {
    const float diff = alpha[p] - alpha[q];
    return diff > 0 ? g : diff < 0 ? -g : 0.0f;
  };
  // Gathered per pixel on the threads, in the order a walk over the pairs row by row would
  // add them (the pair above, the one to the left, then its own right and down pairs).
  const size_t w = size_t(width);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t p = size_t(y) * w + size_t(x);
      float d = d_alpha[p];
      if (y > 0 && counted(p - w, p)) d -= step(p - w, p);
      if (x > 0 && counted(p - 1, p)) d -= step(p - 1, p);
      if (x + 1 < width && counted(p, p + 1)) d += step(p, p + 1);
      if (y + 1 < height && counted(p, p + w)) d += step(p, p + w);
      d_alpha[p] = d;
    }
  double sum = 0;  // the reported value: one sum in pair order
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t p = size_t(y) * w + size_t(x);
      if (x + 1 < width && counted(p, p + 1)) sum += std::abs(double(alpha[p] - alpha[p + 1]));
      if (y + 1 < height && counted(p, p + w)) sum += std::abs(double(alpha[p] - alpha[p + w]));
    }
  return double(lambda) * sum / kept;
}

double occluder_colour_prior(Layer d, std::span<const float> target, float lambda, std::span<float> d_color,
                             std::span<float> d_alpha, std::span<const float> keep) {
  const size_t pixels = d.alpha.size();
  if (d.color.size() != 3 * pixels || target.size() != 3 * pixels || d_color.size() != 3 * pixels ||
      d_alpha.size() != pixels || (!keep.empty() && keep.size() != pixels))
    throw std::invalid_argument("occluder_colour_prior: sizes disagree");
  if (lambda == 0 || pixels == 0) return 0;
  const double kept = kept_pixels(keep, pixels);
  if (kept == 0) return 0;
  const float g = lambda / (3.0f * float(kept));
  auto kept_at = [&](size_t p) { return keep.empty() || keep[p] > 0; };
#pragma omp parallel for schedule(static)
  for (size_t p = 0; p < pixels; ++p) {
    if (!kept_at(p)) continue;
    float da = 0;
    for (int c = 0; c < 3; ++c) {
      const float diff = d.color[3 * p + c] - d.alpha[p] * target[3 * p + c];
      const float sign = diff > 0 ? g : diff < 0 ? -g : 0.0f;
      d_color[3 * p + c] += sign;
      da -= sign * target[3 * p + c];
    }
    d_alpha[p] += da;
  }
  double sum = 0;  // the reported value, in pixel order
  for (size_t p = 0; p < pixels; ++p)
    if (kept_at(p))
      for (int c = 0; c < 3; ++c) sum += std::abs(double(d.color[3 * p + c]) - double(d.alpha[p]) * target[3 * p + c]);
  return double(lambda) * sum / (3.0 * kept);
}

}  // namespace desplat
