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
  int64_t static_unexplained = 0;  // mean |static layer over bg − target| over RGB ≥ tolerance
  // Of those, the ones inside a connected area (counted only with
  // ResidualPenalties::count_in_areas): the static misses that survive a 3×3 opening
  // (erosion, then dilation, of the miss mask). Thin or isolated misses (edges, fine texture
  // not fitted yet) drop out; an area of 3×3 pixels or more keeps all its pixels.
  int64_t static_unexplained_in_areas = 0;
  int64_t composite_unexplained = 0;  // mean |composite − target| over RGB ≥ tolerance
  double penalty = 0;                 // λ_e · mean(A_d · explained) + λ_o · mean((1 − A_d) · owned)
  double static_fraction() const { return pixels ? double(static_unexplained) / double(pixels) : 0.0; }
  double static_area_fraction() const { return pixels ? double(static_unexplained_in_areas) / double(pixels) : 0.0; }
  double composite_fraction() const { return pixels ? double(composite_unexplained) / double(pixels) : 0.0; }
};

// What the residual asks of the distractor layer (docs/METHOD.md §7, growth control).
struct ResidualPenalties {
  float tolerance = 0.1f;         // a pixel is explained when mean |render − target| over RGB < this
  float lambda_explained = 0.0f;  // λ_e: pushes A_d down where the static layer alone explains the pixel
  float lambda_owned = 0.0f;      // λ_o: pulls A_d up where only the composite explains it
  // Also count ViewResidual::static_unexplained_in_areas (distractors.count_connected_misses);
  // off, the opening is skipped and the count stays 0.
  bool count_in_areas = false;
};

// Measures one step's residual. `statics` and `distractor` are the rendered layers (the
// distractor layer may be empty), `composite` and `target` [P·3], `background` the step's.
// With a distractor layer, ADDS the penalties' gradients to d_distractor_alpha [P]:
// λ_e/P where the static layer explains the pixel ("explained"), −λ_o/P where the static
// layer does not, nor at any of the 8 neighbours, and the composite does ("owned" by the
// distractor layer: the inside of an area only it explains). `width` is the image's, in
// pixels. `uncovered_mask`, when not null, is resized to [P] and set to 1 where neither the
// static layer nor the composite explains the pixel: what no Gaussian of either layer
// accounts for yet. `keep` ([P], 0 or 1, optional):
// the user's mask; an ignored pixel is in no count (`pixels` counts the kept ones), gets no
// penalty and is never uncovered.
ViewResidual measure_view_residual(Layer statics, Layer distractor, std::span<const float> composite,
                                   std::span<const float> target, const Background& background, int width,
                                   const ResidualPenalties& penalties, std::span<float> d_distractor_alpha,
                                   std::vector<uint8_t>* uncovered_mask = nullptr, std::span<const float> keep = {});

// Keeps a set pixel of `mask` [height·width] only when its 8 neighbours inside the image
// are set too (a 3×3 erosion): a transient object covers a connected area, while isolated
// unexplained pixels are the static layer's fitting error (fine texture, edges).
void erode_mask(std::vector<uint8_t>& mask, int width, int height);

}  // namespace desplat
