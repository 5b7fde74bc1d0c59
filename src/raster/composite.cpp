// Decomposed compositing, its gradient, and the opacity regularizers (docs/METHOD.md §4).
#include "desplat/raster/composite.hpp"

#include <algorithm>
#include <stdexcept>

namespace desplat {
namespace {

void check_layer(const Layer& l, size_t pixels, const char* what) {
  if (l.alpha.empty() && l.color.empty()) return;
  if (l.alpha.size() != pixels || l.color.size() != 3 * pixels)
    throw std::invalid_argument(std::string("composite: the ") + what + " layer's image sizes disagree");
}

bool has(const Layer& l) { return !l.alpha.empty(); }

void check_background(const Background& bg, size_t pixels) {
  if (!bg.pixels.empty() && bg.pixels.size() != 3 * pixels)
    throw std::invalid_argument("composite: the background image's size disagrees with the layers");
}

}  // namespace

void composite_layers(Layer s, Layer d, const Background& bg, std::span<float> out) {
  const size_t pixels = s.alpha.size();
  check_layer(s, pixels, "static");
  check_layer(d, pixels, "distractor");
  check_background(bg, pixels);
  if (out.size() != 3 * pixels) throw std::invalid_argument("composite: output size disagrees with the layers");
  const bool with_d = has(d);
#pragma omp parallel for schedule(static)
  for (size_t p = 0; p < pixels; ++p) {
    const float ad = with_d ? d.alpha[p] : 0.0f;
    for (int c = 0; c < 3; ++c) {
      const float cd = with_d ? d.color[3 * p + c] : 0.0f;
      out[3 * p + c] = std::clamp(composite_unclamped(s.color[3 * p + c], s.alpha[p], cd, ad, bg.at(p, c)), 0.0f, 1.0f);
    }
  }
}

void composite_layers_backward(Layer s, Layer d, const Background& bg, std::span<const float> d_out,
                               const CompositeGradients& g) {
  const size_t pixels = s.alpha.size();
  check_layer(s, pixels, "static");
  check_layer(d, pixels, "distractor");
  check_background(bg, pixels);
  const bool with_d = has(d), with_bg = !g.background.empty();
  if (d_out.size() != 3 * pixels || g.static_color.size() != 3 * pixels || g.static_alpha.size() != pixels ||
      (with_d && (g.distractor_color.size() != 3 * pixels || g.distractor_alpha.size() != pixels)) ||
      (with_bg && g.background.size() != 3 * pixels))
    throw std::invalid_argument("composite backward: gradient buffer sizes disagree with the layers");
#pragma omp parallel for schedule(static)
  for (size_t p = 0; p < pixels; ++p) {
    const float as = s.alpha[p], ad = with_d ? d.alpha[p] : 0.0f;
    float d_as = 0, d_ad = 0;
    for (int c = 0; c < 3; ++c) {
      const size_t i = 3 * p + c;
      const float cs = s.color[i], cd = with_d ? d.color[i] : 0.0f;
      const float b = bg.at(p, c);
      const float raw = composite_unclamped(cs, as, cd, ad, b);
      const float gc = (raw < 0.0f || raw > 1.0f) ? 0.0f : d_out[i];
      g.static_color[i] = gc * (1.0f - ad);
      d_as -= gc * (1.0f - ad) * b;
      if (with_d) {
        g.distractor_color[i] = gc;
        d_ad -= gc * (cs + (1.0f - as) * b);
      }
      if (with_bg) g.background[i] = gc * (1.0f - ad) * (1.0f - as);
    }
    g.static_alpha[p] = d_as;
    if (with_d) g.distractor_alpha[p] = d_ad;
  }
}

double alpha_regularizers(Layer s, Layer d, float lambda_s, float lambda_d, std::span<float> d_as,
                          std::span<float> d_ad, std::span<const float> keep) {
  const size_t pixels = s.alpha.size();
  if (pixels == 0) return 0;
  if (d_as.size() != pixels || (has(d) && (d.alpha.size() != pixels || d_ad.size() != pixels)) ||
      (!keep.empty() && keep.size() != pixels))
    throw std::invalid_argument("alpha_regularizers: sizes disagree");
  double kept = double(pixels);
  if (!keep.empty()) {
    kept = 0;
    for (float k : keep) kept += k;
    if (kept == 0) return 0;
  }
  double sum_s = 0, sum_d = 0;
  const float gs = -lambda_s / float(kept), gd = lambda_d / float(kept);
  auto k_at = [&](size_t p) { return keep.empty() ? 1.0f : keep[p]; };
  // The gradients per pixel on the threads; the reported sums in pixel order.
#pragma omp parallel for schedule(static)
  for (size_t p = 0; p < pixels; ++p) d_as[p] += k_at(p) * gs;
  for (size_t p = 0; p < pixels; ++p) sum_s += k_at(p) * (1.0 - s.alpha[p]);
  if (has(d)) {
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < pixels; ++p) d_ad[p] += k_at(p) * gd;
    for (size_t p = 0; p < pixels; ++p) sum_d += k_at(p) * d.alpha[p];
  }
  return (lambda_s * sum_s + lambda_d * sum_d) / kept;
}

FloatImage composite_over_background(const RasterOutput& r, const Background& background) {
  FloatImage img{r.width, r.height, 3, std::vector<float>(r.color.size())};
  composite_layers({r.color, r.alpha}, {}, background, img.pixels);
  return img;
}

ViewLayers render_view_layers(const GaussianSet& statics, const GaussianSet* distractors, const Camera& camera,
                              const RasterSettings& settings, const Background& bg,
                              const std::function<void(RasterOutput&)>& recolor_statics) {
  const size_t pixels = size_t(camera.width) * camera.height;
  RasterOutput s, d;
  rasterize_project(statics.view(), camera, settings, s);
  if (recolor_statics) recolor_statics(s);
  rasterize_blend(camera, settings, s);
  const bool with_d = distractors != nullptr && distractors->size() > 0;
  if (with_d) rasterize_forward(distractors->view(), camera, settings, d);
  const Layer ls{s.color, s.alpha};
  const Layer ld = with_d ? Layer{d.color, d.alpha} : Layer{};
  auto rgb = [&] { return FloatImage{camera.width, camera.height, 3, std::vector<float>(3 * pixels)}; };
  ViewLayers out{rgb(),
                 rgb(),
                 rgb(),
                 {camera.width, camera.height, 1, s.alpha},
                 {camera.width, camera.height, 1, with_d ? d.alpha : std::vector<float>(pixels, 0.0f)}};
  composite_layers(ls, {}, bg, out.statics.pixels);
  if (with_d) {
    // The distractor layer alone over the background: it stands in the static layer's place.
    composite_layers(ld, {}, bg, out.distractor.pixels);
  } else {
    for (size_t p = 0; p < pixels; ++p)
      for (int c = 0; c < 3; ++c) out.distractor.pixels[3 * p + c] = bg.at(p, c);
  }
  composite_layers(ls, ld, bg, out.composite.pixels);
  return out;
}

FloatImage distractor_mask(const ViewLayers& layers) {
  FloatImage m = layers.distractor_alpha;
  for (float& a : m.pixels) a = a > kDistractorMaskThreshold ? 1.0f : 0.0f;
  return m;
}

FloatImage side_by_side(const std::vector<const FloatImage*>& images) {
  FloatImage out{0, images.empty() ? 0 : images[0]->height, 3, {}};
  for (const FloatImage* im : images) {
    if (im->height != out.height || (im->channels != 1 && im->channels != 3))
      throw std::invalid_argument("side_by_side: images need equal heights and 1 or 3 channels");
    out.width += im->width;
  }
  out.pixels.assign(size_t(out.width) * out.height * 3, 0.0f);
  int x0 = 0;
  for (const FloatImage* im : images) {
    for (int y = 0; y < im->height; ++y)
      for (int x = 0; x < im->width; ++x)
        for (int c = 0; c < 3; ++c)
          out.pixels[(size_t(y) * out.width + x0 + x) * 3 + c] =
              im->pixels[(size_t(y) * im->width + x) * im->channels + (im->channels == 3 ? c : 0)];
    x0 += im->width;
  }
  return out;
}

FloatImage layers_figure_row(const FloatImage& truth, const ViewLayers& l) {
  const FloatImage mask = distractor_mask(l);
  return side_by_side({&truth, &l.statics, &l.distractor, &l.composite, &mask});
}

}  // namespace desplat
