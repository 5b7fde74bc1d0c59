// Gaussian parameters, stored as a structure of arrays (one contiguous float array
// per attribute) so the per-Gaussian loops read memory linearly and the arrays can
// be handed to the optimizer group by group.
//
// Parameterization (docs/METHOD.md §2), all in the world frame:
//   means           [N, 3]  position μ [world units]
//   log_scales      [N, 3]  s, with per-axis standard deviation exp(s) [world units]
//   quats           [N, 4]  (w, x, y, z); need not be normalized (the kernel does it)
//   opacity_logits  [N]     opacity o = sigmoid(logit)
//   colors          SH mode:  [N, K, 3] with K = (sh_degree + 1)², coefficient-major
//                             (all 3 channels of coefficient 0, then coefficient 1, …);
//                             color = max(Σ_k c_k·Y_k(dir) + 0.5, 0),
//                             dir = normalize(μ − camera center).
//                   RGB mode: [N, 3], color = clamp(rgb, 0, 1)  (distractor Gaussians).
//   features        [N, F]  appearance features z (docs/METHOD.md §10), F = feature_dim; F = 0
//                           when the model has no appearance model. The rasterizer never
//                           reads them; only GaussianSet holds them (GaussianView does not).
#pragma once

#include <cstddef>
#include <span>
#include <vector>

namespace desplat {

enum class ColorMode { SphericalHarmonics, RGB };

// Number of SH coefficients per channel for a degree in [0, 3].
constexpr int sh_coeff_count(int degree) { return (degree + 1) * (degree + 1); }

// Non-owning view of N Gaussians. The arrays must outlive the view.
struct GaussianView {
  std::span<const float> means;           // [N, 3]
  std::span<const float> log_scales;      // [N, 3]
  std::span<const float> quats;           // [N, 4]
  std::span<const float> opacity_logits;  // [N]
  std::span<const float> colors;          // SH: [N, K, 3]; RGB: [N, 3]
  ColorMode color_mode = ColorMode::SphericalHarmonics;
  int sh_degree = 0;  // stored SH degree (0..3); ignored in RGB mode

  std::size_t size() const { return opacity_logits.size(); }
  int color_floats_per_gaussian() const { return color_mode == ColorMode::RGB ? 3 : 3 * sh_coeff_count(sh_degree); }
  // Throws std::invalid_argument when array sizes disagree with N or the SH degree
  // is outside [0, 3].
  void validate() const;
};

// Owning storage with the same layout; view() hands it to the rasterizer.
struct GaussianSet {
  std::vector<float> means, log_scales, quats, opacity_logits, colors;
  ColorMode color_mode = ColorMode::SphericalHarmonics;
  int sh_degree = 0;
  std::vector<float> features;  // [N, feature_dim]
  int feature_dim = 0;

  std::size_t size() const { return opacity_logits.size(); }
  // Resizes every array for n Gaussians (new entries zero, quaternions identity).
  void resize(std::size_t n);
  GaussianView view() const { return {means, log_scales, quats, opacity_logits, colors, color_mode, sh_degree}; }
};

}  // namespace desplat
