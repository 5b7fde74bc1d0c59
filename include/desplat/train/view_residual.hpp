// What one training step sees of its view's residual, for the distractor growth rules of
// docs/METHOD.md §7, growth control: which pixels the static layer alone explains, how many the composite
// still leaves unexplained, and the explained-pixel penalty on the distractor layer.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "desplat/raster/composite.hpp"

namespace desplat {

struct ViewResidual {
  int64_t pixels = 0;
  int64_t static_unexplained = 0;     // mean |static layer over bg − target| over RGB ≥ tolerance
  int64_t composite_unexplained = 0;  // mean |composite − target| over RGB ≥ tolerance
  double penalty = 0;                 // λ_e · mean(A_d · [static explains the pixel])
  double static_fraction() const { return pixels ? double(static_unexplained) / double(pixels) : 0.0; }
  double composite_fraction() const { return pixels ? double(composite_unexplained) / double(pixels) : 0.0; }
};

// Measures one step's residual. `statics` and `distractor` are the rendered layers (the
// distractor layer may be empty), `composite` and `target` [P·3], `background` the step's.
// With lambda_explained > 0 and a distractor layer, ADDS the penalty's gradient
// λ_e/P · [explained] to d_distractor_alpha [P]. `uncovered_mask`, when not null, is
// resized to [P] and set to 1 where neither the static layer nor the composite explains the
// pixel: what no Gaussian of either layer accounts for yet. `keep` ([P], 0 or 1, optional):
// the user's mask; an ignored pixel is in no count (`pixels` counts the kept ones), gets no
// penalty and is never uncovered.
ViewResidual measure_view_residual(Layer statics, Layer distractor, std::span<const float> composite,
                                   std::span<const float> target, const Background& background,
                                   float tolerance, float lambda_explained, std::span<float> d_distractor_alpha,
                                   std::vector<uint8_t>* uncovered_mask = nullptr, std::span<const float> keep = {});

// Keeps a set pixel of `mask` [height·width] only when its 8 neighbours inside the image
// are set too (a 3×3 erosion): a transient object covers a connected area, while isolated
// unexplained pixels are the static layer's fitting error (fine texture, edges).
void erode_mask(std::vector<uint8_t>& mask, int width, int height);

}  // namespace desplat
