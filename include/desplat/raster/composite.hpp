// DeSplat's decomposed compositing (docs/METHOD.md §4): the static layer (C_s, A_s) and a
// training view's distractor layer (C_d, A_d), each rendered separately by the
// rasterizer, are composited over the background:
//
//   C = C_d + (1 − A_d)·C_s + (1 − A_d)(1 − A_s)·bg,   clamped to [0, 1] per channel.
//
// The background bg is one colour (training's random one, the evaluation colour) or one per
// pixel (the background model's sky, docs/METHOD.md §11).
// Colors are the rasterizer's premultiplied [H, W, 3] images, alphas its [H, W]
// accumulated alphas. A view without distractors (every test view, or a training view
// whose distractors were all culled) is the same formula with C_d = 0, A_d = 0:
// C = C_s + (1 − A_s)·bg. Everything here is per pixel and allocation-free except the
// image-returning helpers.
#pragma once

#include <array>
#include <functional>
#include <span>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"
#include "desplat/core/image.hpp"
#include "desplat/raster/raster.hpp"

namespace desplat {

// One pixel channel before the clamp; a template so tests can differentiate it exactly.
template <typename T>
T composite_unclamped(T cs, T as, T cd, T ad, T bg) {
  return cd + (T(1) - ad) * cs + (T(1) - ad) * (T(1) - as) * bg;
}

// A rendered layer: color [P·3] premultiplied, alpha [P]. Empty spans: no such layer.
struct Layer {
  std::span<const float> color, alpha;
};

// What lies behind both layers: one colour, or one per pixel. Does not own `pixels`.
struct Background {
  std::array<float, 3> color{0, 0, 0};
  std::span<const float> pixels;                           // [P·3] when not empty (then `color` is unused)
  Background(const std::array<float, 3>& c) : color(c) {}  // NOLINT: a colour is a background
  explicit Background(std::span<const float> per_pixel) : pixels(per_pixel) {}
  float at(size_t pixel, int channel) const { return pixels.empty() ? color[channel] : pixels[3 * pixel + channel]; }
};

// out[P·3] = the clamped composite of `distractor` over `statics` over `background`.
void composite_layers(Layer statics, Layer distractor, const Background& background, std::span<float> out);

// Gradients of a loss through composite_layers, given ∂L/∂C in `d_out` [P·3]. Where the
// clamp is active the gradient is zero (as PyTorch's clamp). Outputs are overwritten and
// must be sized [P·3] / [P]; the distractor ones may be empty when there is no layer, and
// `background` [P·3] is filled only when given (a per-pixel background that is learned).
struct CompositeGradients {
  std::span<float> static_color, static_alpha, distractor_color, distractor_alpha;
  std::span<float> background = {};
};
void composite_layers_backward(Layer statics, Layer distractor, const Background& background,
                               std::span<const float> d_out, const CompositeGradients& grads);

// λ_s·mean(1 − A_s) + λ_d·mean(A_d) (docs/METHOD.md §4): pushes the static layer to be
// opaque and the distractor layer to be transparent unless the photometric loss needs
// it. Returns the value and ADDS its gradient to d_static_alpha / d_distractor_alpha
// (the distractor ones are skipped when empty). With `keep` ([P], 0 or 1, the user's mask)
// the means run over kept pixels and ignored ones get no gradient.
double alpha_regularizers(Layer statics, Layer distractor, float lambda_static, float lambda_distractor,
                          std::span<float> d_static_alpha, std::span<float> d_distractor_alpha,
                          std::span<const float> keep = {});

// The image a viewer sees of a single render: C + (1 − A)·background, clamped.
FloatImage composite_over_background(const RasterOutput& render, const Background& background);

// Every layer of one view as images over `background`, for figures and desplat_render.
struct ViewLayers {
  FloatImage statics;           // C_s + (1 − A_s)·bg
  FloatImage distractor;        // C_d + (1 − A_d)·bg (the background alone without distractors)
  FloatImage composite;         // the training-time composite
  FloatImage static_alpha;      // [H, W, 1] A_s
  FloatImage distractor_alpha;  // [H, W, 1] A_d (zeros without distractors)
};
// `distractors` may be null or empty (test views, culled views): no second pass is made.
// `statics` is rendered with settings.active_sh_degree; distractors are RGB.
// `recolor_statics`, when set, is called with the static layer's projection before it is
// blended and may change the visible Gaussians' colours (RasterOutput::rgb): the appearance
// model's hook (docs/METHOD.md §10).
ViewLayers render_view_layers(const GaussianSet& statics, const GaussianSet* distractors, const Camera& camera,
                              const RasterSettings& settings, const Background& background,
                              const std::function<void(RasterOutput&)>& recolor_statics = {});

// A pixel is a distractor pixel where A_d exceeds this (docs/METHOD.md §8).
constexpr float kDistractorMaskThreshold = 0.5f;

// The distractor mask of a view: 1 where A_d > kDistractorMaskThreshold, else 0 ([H, W, 1]).
FloatImage distractor_mask(const ViewLayers& layers);

// The paper's Fig. 2 row for a training view: ground truth | static | distractor |
// composite | mask, side by side ([H, 5W, 3]).
FloatImage layers_figure_row(const FloatImage& truth, const ViewLayers& layers);

// Images of equal height side by side; 1-channel images are shown grey.
FloatImage side_by_side(const std::vector<const FloatImage*>& images);

}  // namespace desplat
