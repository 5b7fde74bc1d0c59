// Rendering and scoring a trained model: the static render in a view's look, test-time
// look fitting (the Photo Tourism protocol, docs/METHOD.md §10–11), the layered renders of a
// training view, and the test views' metrics.
#include "desplat/train/trainer.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "desplat/train/background.hpp"
#include "desplat/train/loss.hpp"

namespace desplat {

FloatImage Trainer::render(const Camera& camera, const std::array<float, 3>& background, const ViewLook& look) const {
  LayerPass pass;
  const bool recolor = config_.appearance.enabled && !look.appearance.empty();
  pass.render(gaussians_, camera, raster_settings(), recolor ? &appearance_ : nullptr, look.appearance);
  if (!config_.background.enabled || look.background.empty())
    return composite_over_background(pass.forward, background);
  BackgroundPass sky;
  sky.forward(background_, look.background, camera, config_.background.sh_degree_at(step_), config_.threads);
  return composite_over_background(pass.forward, sky.background());
}

const char* to_string(EvalProtocol p) {
  return p == EvalProtocol::appearance_halves ? "per-image embeddings fitted on the left half, scored on the right half"
                                              : "full image";
}

ViewLook Trainer::fit_look(const TrainView& view, std::span<const float> fit) const {
  if (!has_per_image_models())
    throw std::invalid_argument("fit_look: this model has no per-image appearance or background");
  const Camera& cam = view.camera;
  const size_t pixels = size_t(cam.width) * cam.height;
  if (fit.size() != pixels) throw std::invalid_argument("fit_look: the fit mask does not match view " + view.name);
  std::vector<float> keep(fit.begin(), fit.end());
  if (!view.keep.empty())
    for (size_t p = 0; p < pixels; ++p) keep[p] *= view.keep[p];
  const FloatImage photo = to_float(view.image);
  const bool recolor = config_.appearance.enabled, sky = config_.background.enabled;
  ViewLook look =
      config_.appearance.test_start_from_best_look ? training_look(best_training_look(view, fit)) : mean_look();
  const bool shared = shared_embedding();
  std::vector<float> m_a(look.appearance.size(), 0.0f), v_a(m_a), m_b(look.background.size(), 0.0f), v_b(m_b);
  const RasterSettings rs = raster_settings();
  const int bg_degree = config_.background.sh_degree_at(step_);
  const AdamSettings adam;
  const AppearanceSettings& as = config_.appearance;
  LayerPass pass;
  BackgroundPass sky_pass;
  std::vector<float> composite(3 * pixels), d_composite(3 * pixels);
  auto finite = [](const std::vector<float>& g) {
    return std::all_of(g.begin(), g.end(), [](float x) { return std::isfinite(x); });
  };
  for (int step = 1; step <= as.test_steps; ++step) {
    pass.render(gaussians_, cam, rs, recolor ? &appearance_ : nullptr, look.appearance);
    if (sky) sky_pass.forward(background_, look.background, cam, bg_degree, config_.threads);
    const Background bg = sky ? sky_pass.background() : Background(config_.eval_background);
    composite_layers(pass.layer(), Layer{}, bg, composite);
    photometric_loss(composite, photo.pixels, cam.width, cam.height, config_.ssim_lambda, d_composite, keep);
    pass.d_color.resize(3 * pixels);
    pass.d_alpha.resize(pixels);
    sky_pass.d_image.resize(sky ? 3 * pixels : 0);
    composite_layers_backward(pass.layer(), Layer{}, bg, d_composite,
                              {pass.d_color, pass.d_alpha, {}, {}, sky_pass.d_image});
    const double bc1 = 1.0 - std::pow(double(adam.beta1), step);
    const float step_size = float(as.test_lr / bc1),
                sqrt_bc2 = float(std::sqrt(1.0 - std::pow(double(adam.beta2), step)));
    if (sky) sky_pass.backward(background_, look.background, cam, config_.threads);
    if (recolor) {
      pass.backward(gaussians_, cam, rs, &appearance_, look.appearance);
      std::vector<float>& grad = pass.appearance.d_embedding;
      if (shared)  // one embedding: the background's gradient joins the appearance's
        for (size_t k = 0; k < grad.size(); ++k) grad[k] += sky_pass.d_embedding[k];
      if (!finite(grad)) break;
      adam_span(look.appearance.data(), m_a.data(), v_a.data(), grad.data(), grad.size(), step_size, sqrt_bc2, adam);
      if (shared) look.background = look.appearance;
    }
    if (sky && !shared) {
      const std::vector<float>& grad = sky_pass.d_embedding;
      if (!finite(grad)) break;
      adam_span(look.background.data(), m_b.data(), v_b.data(), grad.data(), grad.size(), step_size, sqrt_bc2, adam);
    }
  }
  return look;
}

ViewLook Trainer::training_look(size_t j) const {
  ViewLook look;
  look.start = data_.train.at(j).name;
  if (config_.appearance.enabled) {
    const std::span<const float> e = appearance_.embedding(j);
    look.appearance.assign(e.begin(), e.end());
  }
  if (config_.background.enabled) {
    const std::span<const float> e = sky_embedding(j);
    look.background.assign(e.begin(), e.end());
  }
  return look;
}

ViewLook Trainer::mean_look() const {
  ViewLook look;
  look.start = "mean";
  if (config_.appearance.enabled) {
    const size_t dim = size_t(config_.appearance.image_dim);
    look.appearance.assign(dim, 0.0f);
    for (size_t j = 0; j < appearance_.views(); ++j)
      for (size_t k = 0; k < dim; ++k) look.appearance[k] += appearance_.embedding(j)[k] / float(appearance_.views());
  }
  if (config_.background.enabled) look.background = shared_embedding() ? look.appearance : background_.mean_embedding();
  return look;
}

size_t Trainer::best_training_look(const TrainView& view, std::span<const float> fit) const {
  if (!has_per_image_models()) throw std::invalid_argument("best_training_look: this model has no per-image looks");
  const int width = view.camera.width, height = view.camera.height;
  if (fit.size() != size_t(width) * height)
    throw std::invalid_argument("best_training_look: the fit mask does not match view " + view.name);
  int factor = 1;
  while (std::max(width, height) / factor > kLookSearchPixels) factor *= 2;
  const Camera cam = downscale_camera(view.camera, factor);
  const FloatImage photo = to_float(factor == 1 ? view.image : downscale_bytes(view.image, factor));
  std::vector<uint8_t> judged(fit.size());
  for (size_t p = 0; p < fit.size(); ++p) judged[p] = fit[p] > 0.5f && (view.keep.empty() || view.keep[p] != 0);
  const std::vector<uint8_t> small = factor == 1 ? judged : downscale_keep(judged, width, height, factor);
  const std::vector<float> keep(small.begin(), small.end());
  size_t best = 0;
  double best_loss = std::numeric_limits<double>::infinity();
  for (size_t j = 0; j < data_.train.size(); ++j) {
    const FloatImage img = render(cam, config_.eval_background, training_look(j));
    const double loss =
        photometric_loss(img.pixels, photo.pixels, cam.width, cam.height, config_.ssim_lambda, {}, keep).loss;
    if (loss < best_loss) best_loss = loss, best = j;  // the first of equals: the lowest index
  }
  return best;
}

ViewLayers Trainer::render_layers(size_t train_view, const std::array<float, 3>& background) const {
  const GaussianSet* d = distractors_.empty() ? nullptr : &distractors_.at(train_view).params;
  std::function<void(RasterOutput&)> recolor;
  AppearancePass pass;
  if (config_.appearance.enabled)  // the static layer in this photo's appearance
    recolor = [&](RasterOutput& fw) {
      pass.forward(appearance_, appearance_.embedding(train_view), gaussians_.params, fw, config_.threads);
    };
  const Camera& camera = data_.train.at(train_view).camera;
  BackgroundPass sky;
  if (config_.background.enabled)  // and over its own background
    sky.forward(background_, sky_embedding(train_view), camera, config_.background.sh_degree_at(step_),
                config_.threads);
  const Background bg = config_.background.enabled ? sky.background() : Background(background);
  return render_view_layers(gaussians_.params, d, camera, raster_settings(), bg, recolor);
}

std::vector<ViewMetrics> Trainer::evaluate(const std::vector<TrainView>& views) const {
  std::vector<ViewMetrics> out;
  for (size_t k = 0; k < views.size(); ++k) {
    const TrainView& v = views[k];
    // In a job of several ranks each view is scored on the rank holding its photo.
    if (rank_of_view(k, ranks_) != rank_) {
      out.push_back(ViewMetrics{.name = v.name});
      continue;
    }
    if (v.image.width != v.camera.width || v.image.height != v.camera.height)
      throw std::invalid_argument("evaluate: view " + v.name + " has no photo of its camera's size on rank " +
                                  std::to_string(rank_));
    // The halves: the right one is scored under either protocol; the left one is where the
    // Photo Tourism protocol fits a model's embeddings (the view's own mask applies to both).
    const int w = v.camera.width, h = v.camera.height;
    std::vector<float> left(size_t(w) * h, 0.0f), right(size_t(w) * h, 0.0f), whole;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t p = size_t(y) * w + x;
        const float keep = v.keep.empty() ? 1.0f : v.keep[p];
        (x < w / 2 ? left : right)[p] = keep;
      }
    ViewMetrics m;
    m.name = v.name;
    if (has_per_image_models()) m.protocol = EvalProtocol::appearance_halves, m.look = fit_look(v, left);
    const FloatImage img = render(v.camera, config_.eval_background, m.look);
    const FloatImage photo = to_float(v.image);
    m.psnr_right_half = psnr(img.pixels, photo.pixels, right);
    m.ssim_right_half = ssim(img.pixels, photo.pixels, w, h, right);
    if (m.protocol == EvalProtocol::appearance_halves) {
      m.psnr = m.psnr_right_half, m.ssim = m.ssim_right_half;
    } else {
      whole.assign(v.keep.begin(), v.keep.end());  // empty when the view has no mask
      m.psnr = psnr(img.pixels, photo.pixels, whole);
      m.ssim = ssim(img.pixels, photo.pixels, w, h, whole);
    }
    out.push_back(std::move(m));
  }
  if (comm_) {
    std::vector<double> scores(4 * out.size(), 0.0);
    for (size_t k = 0; k < out.size(); ++k)
      if (rank_of_view(k, ranks_) == rank_)
        scores[4 * k] = out[k].psnr, scores[4 * k + 1] = out[k].ssim, scores[4 * k + 2] = out[k].psnr_right_half,
                   scores[4 * k + 3] = out[k].ssim_right_half;
    comm_->sum(std::span(scores));
    for (size_t k = 0; k < out.size(); ++k)
      out[k].psnr = scores[4 * k], out[k].ssim = scores[4 * k + 1], out[k].psnr_right_half = scores[4 * k + 2],
      out[k].ssim_right_half = scores[4 * k + 3];
  }
  return out;
}

}  // namespace desplat
