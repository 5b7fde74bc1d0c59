// Per-step residual of a training view (docs/METHOD.md §7, growth control).
#include "desplat/train/view_residual.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace desplat {

namespace {
enum PixelClass : uint8_t { kIgnored = 1, kStaticExplains = 2, kCompositeExplains = 4, kInteriorMiss = 8 };

// Whether `set(p)` holds for pixel (x, y) and its 8 neighbours inside the image: the inside
// of an area, as a transient object covers one. The one 3×3 rule of erode_mask and the
// owned-pixel pull.
template <class Set>
bool interior_of(int width, int height, int x, int y, Set set) {
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int nx = x + dx, ny = y + dy;
      if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
      if (!set(size_t(ny) * width + nx)) return false;
    }
  return true;
}
}  // namespace

ViewResidual measure_view_residual(Layer statics, Layer distractor, std::span<const float> composite,
                                   std::span<const float> target, const Background& bg, int width,
                                   const ResidualPenalties& penalties, std::span<float> d_distractor_alpha,
                                   std::vector<uint8_t>* mask, std::span<const float> keep) {
  const size_t pixels = statics.alpha.size();
  if (!keep.empty() && keep.size() != pixels) throw std::invalid_argument("measure_view_residual: mask size differs");
  if (statics.color.size() != 3 * pixels || composite.size() != 3 * pixels || target.size() != 3 * pixels)
    throw std::invalid_argument("measure_view_residual: image sizes differ");
  if (width <= 0 || pixels % size_t(width) != 0)
    throw std::invalid_argument("measure_view_residual: width does not divide the pixel count");
  const int height = int(pixels / size_t(width));
  const bool has_distractor = !distractor.alpha.empty();
  const float tolerance = penalties.tolerance;
  const bool penalize = (penalties.lambda_explained > 0 || penalties.lambda_owned > 0) && has_distractor;
  if (penalize && (distractor.alpha.size() != pixels || d_distractor_alpha.size() != pixels))
    throw std::invalid_argument("measure_view_residual: distractor layer size differs");
  if (mask) mask->resize(pixels);         // every pixel is written below
  thread_local std::vector<uint8_t> cls;  // reused from step to step: no per-step allocation
  cls.resize(pixels);
  ViewResidual r;
  r.pixels = int64_t(pixels);
  if (!keep.empty()) r.pixels = std::count_if(keep.begin(), keep.end(), [](float k) { return k > 0; });
  // Per pixel on the threads (integer counts: the same sums in any order).
  int64_t static_unexplained = 0, composite_unexplained = 0;
  uint8_t* const cls_of = cls.data();  // thread_local: each thread would see its own vector
#pragma omp parallel for schedule(static) reduction(+ : static_unexplained, composite_unexplained)
  for (size_t p = 0; p < pixels; ++p) {
    if (!keep.empty() && keep[p] == 0) {  // ignored by the user: neither explained nor not
      cls_of[p] = kIgnored;
      if (mask) (*mask)[p] = 0;
      continue;
    }
    float static_err = 0, composite_err = 0;
    const float transmittance = 1.0f - statics.alpha[p];
    for (int c = 0; c < 3; ++c) {
      const float s = std::clamp(statics.color[3 * p + c] + transmittance * bg.at(p, c), 0.0f, 1.0f);
      static_err += std::abs(s - target[3 * p + c]);
      composite_err += std::abs(composite[3 * p + c] - target[3 * p + c]);
    }
    // NaN counts as unexplained: !(err < tol).
    const bool static_explains = static_err < 3.0f * tolerance;
    static_unexplained += !static_explains;
    const bool composite_explains = composite_err < 3.0f * tolerance;
    composite_unexplained += !composite_explains;
    if (mask) (*mask)[p] = !static_explains && !composite_explains;
    cls_of[p] = uint8_t((static_explains ? kStaticExplains : 0) | (composite_explains ? kCompositeExplains : 0));
  }
  r.static_unexplained = static_unexplained, r.composite_unexplained = composite_unexplained;
  const float per_pixel = r.pixels ? 1.0f / float(r.pixels) : 0.0f;
  const float explained_weight = penalties.lambda_explained * per_pixel;
  const float owned_weight = penalize ? penalties.lambda_owned * per_pixel : 0.0f;
  // Interior misses (a miss whose 8 neighbours inside the image are missed too), for the
  // owned-pixel pull and the opening below; only when one of them asks.
  const auto missed = [&](size_t q) { return !(cls[q] & (kIgnored | kStaticExplains)); };
  if (owned_weight > 0 || penalties.count_in_areas)
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        if (missed(p) && interior_of(width, height, x, y, missed)) cls[p] |= kInteriorMiss;
      }
  // The 3×3 opening: a miss counts when it or a neighbour is an interior miss.
  if (penalties.count_in_areas)
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        if (missed(p) && !interior_of(width, height, x, y, [&](size_t q) { return !(cls[q] & kInteriorMiss); }))
          ++r.static_unexplained_in_areas;
      }
  if (!penalize || r.pixels == 0) return r;
  double explained_sum = 0, owned_sum = 0;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t p = size_t(y) * width + x;
      if (cls[p] & kIgnored) continue;
      if (cls[p] & kStaticExplains) {  // a distractor here can only be memorizing static detail
        explained_sum += distractor.alpha[p];
        d_distractor_alpha[p] += explained_weight;
      } else if (owned_weight > 0 && (cls[p] & kCompositeExplains) && (cls[p] & kInteriorMiss)) {
        // Inside an area the static layer misses; its fine detail not yet fitted is thin.
        owned_sum += 1.0f - distractor.alpha[p];  // the distractor layer is this pixel's explanation
        d_distractor_alpha[p] -= owned_weight;
      }
    }
  r.penalty = (double(penalties.lambda_explained) * explained_sum + double(penalties.lambda_owned) * owned_sum) /
              double(r.pixels);
  return r;
}

void erode_mask(std::vector<uint8_t>& mask, int width, int height) {
  if (width < 0 || height < 0 || mask.size() != size_t(width) * size_t(height))
    throw std::invalid_argument("erode_mask: mask size does not match the image");
  const std::vector<uint8_t> in = mask;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      mask[size_t(y) * width + x] = interior_of(width, height, x, y, [&](size_t q) { return in[q] != 0; });
}

}  // namespace desplat
