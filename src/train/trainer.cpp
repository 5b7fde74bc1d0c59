// The training loop: one view per step; the static and the view's distractor layer are
// rendered separately and composited over a random background; photometric loss plus
// the opacity regularizers; backward through the composite into both; Adam; density
// control (docs/METHOD.md §4–7).
#include "desplat/train/trainer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <omp.h>
#include <stdexcept>

#include "desplat/train/background.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/init.hpp"
#include "desplat/train/loss.hpp"
#include "desplat/train/mask_coherence.hpp"
#include "desplat/train/view_residual.hpp"

namespace desplat {
namespace {

// `leave_out` [points] or empty: 1 for the points that start no static Gaussian.
GaussianSet initial_gaussians(const TrainingData& data, const TrainConfig& cfg, std::mt19937_64& rng,
                              const std::vector<uint8_t>& leave_out) {
  if (!leave_out.empty()) {
    std::vector<std::array<float, 3>> xyz;
    std::vector<std::array<uint8_t, 3>> rgb;
    for (size_t i = 0; i < data.points.size(); ++i)
      if (!leave_out[i]) {
        xyz.push_back(data.points[i]);
        rgb.push_back(data.colors[i]);
      }
    if (!xyz.empty()) return init_gaussians_from_points(xyz, rgb, cfg.sh_degree, rng());
  }
  if (!data.points.empty()) return init_gaussians_from_points(data.points, data.colors, cfg.sh_degree, rng());
  // No points (docs/METHOD.md §5): uniform in a cube, random colors.
  std::uniform_real_distribution<float> u(-cfg.random_init_extent, cfg.random_init_extent);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<std::array<float, 3>> xyz(cfg.random_init_points);
  std::vector<std::array<uint8_t, 3>> rgb(cfg.random_init_points);
  for (size_t i = 0; i < xyz.size(); ++i) {
    xyz[i] = {u(rng), u(rng), u(rng)};
    rgb[i] = {uint8_t(byte(rng)), uint8_t(byte(rng)), uint8_t(byte(rng))};
  }
  return init_gaussians_from_points(xyz, rgb, cfg.sh_degree, rng());
}

}  // namespace

Camera downscale_camera(const Camera& c, int factor) {
  Camera out = c;
  out.fx /= factor, out.fy /= factor, out.cx /= factor, out.cy /= factor;
  out.width = std::max(1, c.width / factor);
  out.height = std::max(1, c.height / factor);
  return out;
}

TrainConfig effective_config(TrainConfig config, const TrainingData& data) {
  // Transient points are DeSplat's: without distractors the model is the Splatfacto
  // baseline (--static-only, the bench's static-only runs) and starts from every point.
  if (!config.distractors.enabled) config.transient_points.action = TransientPointAction::keep;
  // The background's opaque term is left out for a steady sky (BackgroundSettings, docs/METHOD.md
  // §11): photos of one exposure and colour balance that show open sky, by --effects auto's
  // evidence from the SfM tracks (none: the term stays).
  if (config.background.enabled && config.background.opaque_off_for_steady_sky && config.background.lambda_opaque > 0 &&
      !data.point_train_views.empty() && data.point_train_views.size() == data.points.size()) {
    const EffectsEvidence ev = examine_effects(data);
    if (ev.judged_views >= 3 && !ev.appearance && ev.background) config.background.lambda_opaque = 0.0f;
  }
  return config;
}

Trainer::Trainer(const TrainingData& data, TrainConfig config)
    : data_(data), config_(std::move(config)), rng_(config_.seed) {
  // Adam, the loss and the initialization are plain `omp parallel` loops: without this a
  // --threads 1 run would still start a team per core (and spin in it).
  if (config_.threads > 0) omp_set_num_threads(config_.threads);
  if (data_.train.empty()) throw std::invalid_argument("training needs at least one training view");
  for (const TrainView& v : data_.train) {
    v.camera.validate();
    if (v.image.width != v.camera.width || v.image.height != v.camera.height || v.image.channels != 3)
      throw std::invalid_argument("training view " + v.name + ": image size does not match its camera");
  }
  for (const auto* views : {&data_.train, &data_.test})
    for (const TrainView& v : *views) {
      if (v.keep.empty()) continue;
      if (v.keep.size() != size_t(v.camera.width) * v.camera.height)
        throw std::invalid_argument("view " + v.name + ": its mask has " + std::to_string(v.keep.size()) +
                                    " values for " + std::to_string(v.camera.width) + "x" +
                                    std::to_string(v.camera.height) + " pixels");
      if (std::any_of(v.keep.begin(), v.keep.end(), [](uint8_t k) { return k > 1; }))
        throw std::invalid_argument("view " + v.name + ": its mask must hold only 0 (ignore) and 1 (use)");
      // A view with no kept pixel has nothing to train on and no score (its PSNR would be 0/0).
      if (std::none_of(v.keep.begin(), v.keep.end(), [](uint8_t k) { return k == 1; }))
        throw std::invalid_argument("view " + v.name + ": its mask keeps no pixel (it is all black), so the view has "
                                    "nothing to train on or score; fix the mask, or leave the view out");
    }
  // SSIM (the loss, the evaluation) needs 11×11 pixels, at the coarsest level of the
  // resolution schedule too: say so before training rather than fail at its first step.
  const int coarsest = config_.downscale_at(0);
  auto check_size = [&](const TrainView& v, int factor, const char* kind) {
    const int w = std::max(1, v.camera.width / factor), h = std::max(1, v.camera.height / factor);
    if (w >= kSsimWindow && h >= kSsimWindow) return;
    std::string where = std::to_string(v.camera.width) + "x" + std::to_string(v.camera.height) + " px";
    if (factor > 1)
      where += ", and " + std::to_string(w) + "x" + std::to_string(h) + " px in the first steps (the resolution " +
               "schedule starts at 1/" + std::to_string(factor) + ", num_downscales " +
               std::to_string(config_.num_downscales) + ")";
    throw std::invalid_argument(std::string(kind) + " view " + v.name + " is " + where + ": the SSIM loss needs at least " +
                                std::to_string(kSsimWindow) + "x" + std::to_string(kSsimWindow) +
                                " px; use a smaller --downscale" + (factor > 1 ? " or a lower num_downscales" : ""));
  };
  for (const TrainView& v : data_.train) check_size(v, coarsest, "training");
  for (const TrainView& v : data_.test) check_size(v, 1, "test");
  config_ = effective_config(std::move(config_), data_);
  std::vector<uint8_t> transient;
  if (config_.transient_points.action != TransientPointAction::keep) {
    transient = transient_points(data_, config_.transient_points);
    for (const uint8_t t : transient) transient_point_count += t;
  }
  GaussianSet initial = initial_gaussians(data_, config_, rng_, transient);
  if (config_.appearance.enabled) {
    // docs/METHOD.md §10: z_i starts as Fourier features of the Gaussian's position.
    config_.appearance.validate();
    initial.feature_dim = config_.appearance.feature_dim();
    initial.features = fourier_features(initial.means, config_.appearance.fourier_frequencies);
  }
  gaussians_ = TrainableGaussians(std::move(initial));
  {
    std::vector<Camera> cameras;  // training views in name order: the capture order
    for (const TrainView& v : data_.train) cameras.push_back(v.camera);
    camera_path_ = desplat::camera_path(cameras, data_.points, config_.densify.camera_path);
    // Only the (off by default) distractor size rule needs it; the camera path has it already
    // when its own rule is on.
    if (config_.distractors.enabled && config_.distractors.size_threshold_at_scene_depth)
      scene_depth_ = camera_path_.median_depth > 0 ? camera_path_.median_depth : median_scene_depth(cameras, data_.points);
  }
  if (config_.distractors.enabled) {
    std::vector<Camera> cameras;
    for (const TrainView& v : data_.train) cameras.push_back(v.camera);
    check_initial_distractors(cameras, config_.distractors);
    distractors_.reserve(data_.train.size());
    for (const TrainView& v : data_.train) distractors_.emplace_back(init_distractors(v.camera, config_.distractors, rng_()));
    if (config_.transient_points.action == TransientPointAction::seed && transient_point_count > 0)
      seed_from_transient_points(transient);
    view_static_unexplained.assign(data_.train.size(), 0.0f);
    view_composite_unexplained.assign(data_.train.size(), 0.0f);
    view_seed_due.assign(data_.train.size(), 0);
  }
  if (config_.appearance.enabled) appearance_ = AppearanceModel(config_.appearance, data_.train.size(), rng_());
  if (config_.background.enabled) background_ = BackgroundModel(config_.background, data_.train.size(), rng_());
  if (shared_embedding() && config_.background.image_dim != config_.appearance.image_dim)
    throw std::invalid_argument("background.image_dim (" + std::to_string(config_.background.image_dim) +
                                ") must equal appearance.image_dim (" + std::to_string(config_.appearance.image_dim) +
                                ") while background.share_appearance_embedding is on");
  downscaled_.resize(data_.train.size());
  warn = [](const std::string& msg) { std::fprintf(stderr, "warning: %s\n", msg.c_str()); };
}

void Trainer::cull_camera_path(RefineReport& report) {
  const GaussianSet& g = gaussians_.params;
  const std::vector<uint8_t> on_path = on_camera_path(camera_path_, g.means, g.log_scales, g.quats);
  const int64_t in_gaps = std::count(on_path.begin(), on_path.end(), uint8_t(kInBlindGap));
  const int64_t culled = std::count(on_path.begin(), on_path.end(), uint8_t(kInTube)) + in_gaps;
  if (culled == 0) return;
  std::vector<uint8_t> keep(on_path.size());
  for (size_t i = 0; i < on_path.size(); ++i) keep[i] = !on_path[i];
  gaussians_.keep(keep);
  report.on_camera_path += culled;
  report.culled += culled;
  camera_path_culled += culled;
  camera_path_blind_gap_culled += in_gaps;
}

size_t Trainer::distractor_count() const {
  size_t n = 0;
  for (const TrainableGaussians& d : distractors_) n += d.size();
  return n;
}

RasterSettings Trainer::raster_settings() const {
  RasterSettings rs;
  rs.num_threads = config_.threads;
  rs.isa = config_.kernel_isa;
  rs.active_sh_degree = config_.sh_degree_at(step_);
  return rs;
}

int Trainer::next_view() {
  if (view_order_pos >= static_cast<int64_t>(view_order.size())) {
    view_order.resize(data_.train.size());
    std::iota(view_order.begin(), view_order.end(), 0);
    std::shuffle(view_order.begin(), view_order.end(), rng_);
    view_order_pos = 0;
  }
  return view_order[view_order_pos++];
}

const FloatImage& Trainer::target_at(int view, int factor) {
  const ByteImage* photo = &data_.train[view].image;
  if (factor > 1) {
    int level = 0;
    while ((2 << level) < factor) ++level;
    auto& cache = downscaled_[view];
    while (static_cast<int>(cache.size()) <= level) cache.push_back(downscale_bytes(*photo, 2 << cache.size()));
    photo = &cache[level];
  }
  target_.width = photo->width, target_.height = photo->height, target_.channels = photo->channels;
  target_.pixels.resize(photo->pixels.size());
  to_float(*photo, target_.pixels);
  return target_;
}

std::vector<uint8_t> downscale_keep(const std::vector<uint8_t>& keep, int width, int height, int factor) {
  // A coarse pixel is kept only when every pixel it covers is: one that mixes in an ignored
  // pixel (whose photo value is meaningless) is ignored too.
  const int w = std::max(1, width / factor), h = std::max(1, height / factor);
  std::vector<uint8_t> out(size_t(w) * h, 1);
  for (int y = 0; y < h * factor && y < height; ++y)
    for (int x = 0; x < w * factor && x < width; ++x)
      if (keep[size_t(y) * width + x] == 0) out[size_t(y / factor) * w + x / factor] = 0;
  return out;
}

std::span<const float> Trainer::keep_at(int view, int factor) {
  const std::vector<uint8_t>* mask = &data_.train[view].keep;
  if (mask->empty()) return {};
  if (factor > 1) {
    int level = 0;
    while ((2 << level) < factor) ++level;
    if (downscaled_keep_.empty()) downscaled_keep_.resize(data_.train.size());
    auto& cache = downscaled_keep_[view];
    const Camera& cam = data_.train[view].camera;
    while (static_cast<int>(cache.size()) <= level)
      cache.push_back(downscale_keep(*mask, cam.width, cam.height, 2 << cache.size()));
    mask = &cache[level];
  }
  keep_.assign(mask->begin(), mask->end());
  return keep_;
}

bool Trainer::shared_embedding() const {
  return config_.background.share_appearance_embedding && config_.appearance.enabled && config_.background.enabled;
}

std::span<const float> Trainer::sky_embedding(size_t view) const {
  return shared_embedding() ? appearance_.embedding(view) : background_.embedding(view);
}

// The rows Adam updates this step: the Gaussians the rasterizer found visible (the only ones
// with a gradient), or every row (empty span) when selective Adam is off.
std::span<const uint8_t> Trainer::adam_rows(const RasterOutput& forward) const {
  return config_.selective_adam ? std::span<const uint8_t>(forward.visible) : std::span<const uint8_t>();
}

StepStats Trainer::step() {
  StepStats stats;
  stats.step = step_;
  const int view = next_view();
  const int factor = config_.downscale_at(step_);
  if (factor == 1) {  // the schedule never goes back to a coarser level: give the pyramid's memory back
    for (std::vector<ByteImage>& levels : downscaled_)
      if (!levels.empty()) std::vector<ByteImage>().swap(levels);
    std::vector<std::vector<std::vector<uint8_t>>>().swap(downscaled_keep_);
  }
  const Camera cam = downscale_camera(data_.train[view].camera, factor);
  const FloatImage& target = target_at(view, factor);
  const std::span<const float> keep = keep_at(view, factor);
  const size_t pixels = size_t(cam.width) * cam.height;
  const RasterSettings rs = raster_settings();
  std::array<float, 3> bg_color = config_.eval_background;
  if (config_.random_background && !config_.background.enabled) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    bg_color = {u(rng_), u(rng_), u(rng_)};
  }
  // A view whose distractors were all culled has no second pass at all.
  TrainableGaussians* distractors = nullptr;
  if (config_.distractors.enabled && distractors_[view].size() > 0) distractors = &distractors_[view];
  stats.view_distractors = distractors ? distractors->size() : 0;
  StepProfiler profile;
  const AppearanceModel* look = config_.appearance.enabled ? &appearance_ : nullptr;
  const std::span<const float> embedding = look ? appearance_.embedding(size_t(view)) : std::span<const float>();

  // 1. Render each layer, and the background behind them.
  const bool learned_bg = config_.background.enabled;
  if (learned_bg)
    profile.time(&StepTimings::background, [&] {
      background_pass_.forward(background_, sky_embedding(size_t(view)), cam,
                               config_.background.sh_degree_at(step_), config_.threads);
    });
  const Background bg = learned_bg ? background_pass_.background() : Background(bg_color);
  profile.time(&StepTimings::forward, [&] { static_pass_.render(gaussians_, cam, rs, look, embedding); });
  const double appearance_forward = static_pass_.appearance_seconds;
  stats.static_pairs = static_pass_.forward.evaluated_pairs;
  stats.static_visible = size_t(std::count(static_pass_.forward.visible.begin(), static_pass_.forward.visible.end(), 1));
  if (distractors)
    profile.time(&StepTimings::distractor, [&] { distractor_pass_.render(*distractors, cam, rs); });

  // 2. Composite, loss, and the loss's gradient with respect to each layer (docs/METHOD.md §4).
  profile.time(&StepTimings::loss, [&] {
    const Layer statics = static_pass_.layer();
    const Layer distractor = distractors ? distractor_pass_.layer() : Layer{};
    composite_.resize(3 * pixels);
    composite_layers(statics, distractor, bg, composite_);
    d_composite_.resize(3 * pixels);
    const PhotometricLoss loss =
        photometric_loss(composite_, target.pixels, cam.width, cam.height, config_.ssim_lambda, d_composite_, keep);
    static_pass_.d_color.resize(3 * pixels);
    static_pass_.d_alpha.resize(pixels);
    distractor_pass_.d_color.resize(distractors ? 3 * pixels : 0);
    distractor_pass_.d_alpha.resize(distractors ? pixels : 0);
    background_pass_.d_image.resize(learned_bg ? 3 * pixels : 0);
    composite_layers_backward(statics, distractor, bg, d_composite_,
                              {static_pass_.d_color, static_pass_.d_alpha, distractor_pass_.d_color,
                               distractor_pass_.d_alpha, background_pass_.d_image});
    stats.loss = loss.loss;
    // With a learned background the static layer need not be opaque everywhere (the sky is
    // the background's): L_bg replaces λ_s (docs/METHOD.md §11).
    if (config_.distractors.enabled && config_.distractors.regularize)
      stats.loss += alpha_regularizers(statics, distractor, learned_bg ? 0.0f : config_.distractors.lambda_static,
                                       config_.distractors.lambda_distractor, static_pass_.d_alpha,
                                       distractor_pass_.d_alpha, keep);
    if (learned_bg)
      stats.loss += background_alpha_loss(background_pass_.image, target.pixels, statics, distractor, cam.width,
                                          cam.height, config_.background, static_pass_.d_alpha, keep);
    if (distractors && config_.distractors.regularize && config_.distractors.lambda_mask_tv > 0)
      stats.loss += mask_total_variation(distractor.alpha, cam.width, cam.height,
                                         config_.distractors.lambda_mask_tv, distractor_pass_.d_alpha, keep);
    // Like the owned-pixel pull, only once the static layer has had its chance (owned_after).
    if (distractors && config_.distractors.regularize && config_.distractors.lambda_occluder_colour > 0 &&
        step_ >= config_.distractors.owned_after)
      stats.loss += occluder_colour_prior(distractor, target.pixels, config_.distractors.lambda_occluder_colour,
                                          distractor_pass_.d_color, distractor_pass_.d_alpha, keep);
    if (config_.distractors.enabled) {
      const DistractorSettings& ds = config_.distractors;
      const ViewResidual residual = measure_view_residual(
          statics, distractor, composite_, target.pixels, bg, cam.width,
          ResidualPenalties{ds.explained_tolerance, ds.lambda_explained,
                            step_ >= ds.owned_after ? ds.lambda_owned : 0.0f, ds.count_connected_misses},
          distractor_pass_.d_alpha, ds.reseed_starved_views || ds.seed_uncovered ? &uncovered_mask_ : nullptr, keep);
      stats.loss += residual.penalty;
      // What the growth rules count as the static layer's misses (DistractorSettings).
      view_static_unexplained[view] =
          float(ds.count_connected_misses ? residual.static_area_fraction() : residual.static_fraction());
      view_composite_unexplained[view] = float(residual.composite_fraction());
    }
    stats.psnr = psnr(composite_, target.pixels, keep);
  });

  // 3. Backward through each layer's rasterization.
  profile.time(&StepTimings::backward, [&] { static_pass_.backward(gaussians_, cam, rs, look, embedding); });
  // The appearance model's share of the static passes is reported on its own.
  profile.timings.forward -= appearance_forward;
  profile.timings.backward -= static_pass_.appearance_seconds - appearance_forward;
  profile.timings.appearance += static_pass_.appearance_seconds;
  const bool shared = shared_embedding();
  if (learned_bg)
    profile.time(&StepTimings::background, [&] {
      background_pass_.backward(background_, sky_embedding(size_t(view)), cam, config_.threads);
      const size_t dim = size_t(config_.background.image_dim);
      d_embeddings_.assign(background_.image_embeddings.size(), 0.0f);
      if (!shared) std::copy_n(background_pass_.d_embedding.begin(), dim, d_embeddings_.begin() + size_t(view) * dim);
      if (!background_.adam_update(background_pass_.d_mlp, d_embeddings_))
        warn("step " + std::to_string(step_) + ": the background model's gradient is not finite; its update was skipped");
    });
  if (look)
    profile.time(&StepTimings::appearance, [&] {
      const size_t dim = size_t(config_.appearance.image_dim);
      d_embeddings_.assign(appearance_.image_embeddings.size(), 0.0f);
      std::copy_n(static_pass_.appearance.d_embedding.begin(), dim, d_embeddings_.begin() + size_t(view) * dim);
      if (shared)
        for (size_t k = 0; k < dim; ++k) d_embeddings_[size_t(view) * dim + k] += background_pass_.d_embedding[k];
      if (!appearance_.adam_update(static_pass_.appearance.d_mlp, d_embeddings_))
        warn("step " + std::to_string(step_) + ": the appearance model's gradient is not finite; its update was skipped");
    });
  if (distractors)
    profile.time(&StepTimings::distractor, [&] { distractor_pass_.backward(*distractors, cam, rs); });

  // 4. Statistics, Adam and density control: the static buffer …
  const int image_size = std::max(cam.width, cam.height);
  // Exponential decay of the means' rate from lr.means to means_lr_final; the distractors'
  // means follow the same factor.
  const double progress = std::min(1.0, double(step_) / double(std::max<int64_t>(1, config_.means_lr_decay_steps)));
  LearningRates lr = config_.lr;
  lr.means = float(std::exp(std::log(config_.lr.means) * (1 - progress) + std::log(config_.means_lr_final) * progress));
  const double decay = double(lr.means) / double(config_.lr.means);
  profile.time(&StepTimings::optimizer, [&] {
    // Adam first: the rows it updates are the rasterizer's visible ones, before the
    // statistics hide those centred on ignored pixels (they still have a gradient).
    const int sh_bands = rs.active_sh_degree + 1;
    gaussians_.adam_update(static_pass_.grads, lr, AdamSettings{}, 3 * sh_bands * sh_bands,
                           adam_rows(static_pass_.forward));
    // Behind this view's distractor mask a static Gaussian is not seen (hide_behind_distractors).
    const bool hide_behind = distractors && config_.densify.stats.hide_behind_distractors;
    hide_unseen_centers(static_pass_.forward, keep, hide_behind ? distractor_pass_.forward.alpha : std::span<const float>());
    if (step_ < config_.densify.stop_split_at) {
      // Judged per pixel the static layer is seen on (gradient_per_seen_pixel).
      const float seen_scale = distractors && config_.densify.stats.gradient_per_seen_pixel
                                   ? seen_pixel_gradient_scale(keep, distractor_pass_.forward.alpha)
                                   : 1.0f;
      gaussians_.accumulate_statistics(static_pass_.forward, static_pass_.grads, config_.densify.stats, seen_scale);
    }
    stats.nonfinite_pruned = prune_nonfinite(gaussians_, [] { return std::string("static Gaussian"); });
    stats.refine = refine_gaussians(gaussians_, config_.densify, step_, image_size,
                                    static_cast<int>(data_.train.size()), rng_);
    if (stats.refine.ran && !camera_path_.empty()) cull_camera_path(stats.refine);
  });

  // … and the view's distractor buffer (its statistics are kept after densification stops:
  // culling unseen distractors needs them), then every view's refinement when it is due.
  const bool refine_distractors_now =
      distractor_refine_due(step_, static_cast<int>(data_.train.size()), config_.densify, config_.distractors);
  // A view without distractors that is not due for re-seeding costs nothing here.
  if (distractors || refine_distractors_now || (config_.distractors.enabled && view_seed_due[view])) {
    profile.time(&StepTimings::distractor, [&] {
      if (distractors) {
        LearningRates dlr = config_.distractors.lr;
        dlr.means = float(dlr.means * decay);
        distractors->adam_update(distractor_pass_.grads, dlr, AdamSettings{}, -1, adam_rows(distractor_pass_.forward));
        hide_unseen_centers(distractor_pass_.forward, keep, {});
        distractors->accumulate_statistics(distractor_pass_.forward, distractor_pass_.grads, config_.densify.stats);
        stats.nonfinite_pruned +=
            prune_nonfinite(*distractors, [&] { return "distractor of view " + data_.train[view].name; });
      }
      stats.reseeded = seed_if_due(view, cam, target);
      if (refine_distractors_now) refine_all_distractors(image_size, factor, stats);
    });
  }
  stats.timings = profile.timings;
  stats.gaussians = gaussians_.size();
  ++step_;
  return stats;
}

void Trainer::refine_all_distractors(int image_size, int factor, StepStats& stats) {
  stats.distractor_refine.ran = true;
  const DistractorSettings& ds = config_.distractors;
  for (size_t v = 0; v < distractors_.size(); ++v) {
    TrainableGaussians& d = distractors_[v];
    const Camera& full = data_.train[v].camera;
    const int64_t pixels = int64_t(full.width) * full.height;
    if (d.size() > 0) {
      ViewRefinement r;
      r.view = int(v);
      r.before = int64_t(d.size());
      // Idle distractors go first, so the cap's room goes to the ones the view needs.
      r.idle = cull_idle_distractors(d, downscale_camera(full, factor), factor, ds);
      r.budget = distractor_growth_budget(d.size(), view_static_unexplained[v], pixels, ds);
      if (ds.max_alpha_sum > 0) {
        r.alpha_sum = distractor_alpha_sum(d.params.view(), full);
        const int64_t by_alpha = alpha_sum_budget(d.size(), r.alpha_sum, view_static_unexplained[v], pixels, ds);
        if (by_alpha != kUnlimitedGrowth && (r.budget == kUnlimitedGrowth || by_alpha < r.budget)) r.budget = by_alpha;
      }
      r.report = refine_distractors(d, config_.densify, ds, step_, image_size, rng_, r.budget, scene_depth_);
      r.after = int64_t(d.size());
      stats.distractor_refine += r.report;
      stats.distractor_refinements.push_back(r);
      // An emptied view gives its memory back; it is not rendered until it is re-seeded.
      if (d.size() == 0) {
        GaussianSet empty;
        empty.color_mode = ColorMode::RGB;
        d = TrainableGaussians(std::move(empty));
      }
    }
    const bool starved = ds.reseed_starved_views && distractor_buffer_starved(d.size(), view_static_unexplained[v], pixels);
    const bool uncovered = ds.seed_uncovered && uncovered_seed_count(d.size(), view_static_unexplained[v],
                                                                     view_composite_unexplained[v], pixels, ds) > 0;
    view_seed_due[v] = step_ < config_.densify.stop_split_at && seeding_settled() && (starved || uncovered);
  }
}

void Trainer::seed_from_transient_points(const std::vector<uint8_t>& transient) {
  // One distractor on the pixel each transient point projects to, in every training view
  // that observes it: the same seeds the growth rules place on uncovered pixels.
  for (size_t v = 0; v < data_.train.size(); ++v) {
    const TrainView& view = data_.train[v];
    const Camera& c = view.camera;
    std::vector<uint8_t> mask(size_t(c.width) * c.height, 0);
    size_t count = 0;
    for (size_t i = 0; i < transient.size(); ++i) {
      if (!transient[i]) continue;
      const std::vector<int32_t>& observers = data_.point_train_views[i];
      if (!std::binary_search(observers.begin(), observers.end(), int32_t(v))) continue;
      const long long pixel = c.pixel_of(data_.points[i]);
      if (pixel < 0 || (!view.keep.empty() && view.keep[size_t(pixel)] == 0)) continue;  // off screen or ignored
      uint8_t& m = mask[size_t(pixel)];
      count += !m;
      m = 1;
    }
    if (count == 0) continue;
    const GaussianSet seeds = reseed_distractors(c, mask, to_float(view.image).pixels, count, config_.distractors, rng_());
    distractors_[v].append(seeds);
    transient_seeded += int64_t(seeds.size());
  }
}

bool resolution_settled(const TrainConfig& config, int64_t step, int64_t period) {
  return config.downscale_at(step) == config.downscale_at(std::max<int64_t>(0, step - period));
}

void hide_unseen_centers(RasterOutput& fw, std::span<const float> keep, std::span<const float> hiding_alpha) {
  if (keep.empty() && hiding_alpha.empty()) return;
  for (size_t i = 0; i < fw.visible.size(); ++i) {
    if (!fw.visible[i]) continue;
    const float x = fw.means2d[2 * i], y = fw.means2d[2 * i + 1];
    if (!(x >= 0 && y >= 0 && x < float(fw.width) && y < float(fw.height))) continue;
    const size_t p = size_t(y) * size_t(fw.width) + size_t(x);
    if ((!keep.empty() && keep[p] == 0) || (!hiding_alpha.empty() && hiding_alpha[p] > kDistractorMaskThreshold))
      fw.visible[i] = 0;
  }
}

float seen_pixel_gradient_scale(std::span<const float> keep, std::span<const float> distractor_alpha) {
  if (distractor_alpha.empty()) return 1.0f;
  double kept = 0, seen = 0;
  for (size_t p = 0; p < distractor_alpha.size(); ++p) {
    const double k = keep.empty() ? 1.0 : double(keep[p]);
    kept += k;
    seen += k * (1.0 - double(distractor_alpha[p]));
  }
  return seen > 0 ? float(kept / seen) : 1.0f;
}

bool seeding_allowed(const TrainConfig& config, int64_t step, int64_t period) {
  if (step < config.distractors.seed_after || !resolution_settled(config, step, period)) return false;
  if (!config.distractors.seed_waits_after_reset) return true;
  for (int64_t s = step; s > std::max<int64_t>(0, step - period); --s)
    if (opacity_reset_due(config.densify, s)) return false;
  return true;
}

bool Trainer::seeding_settled() const {
  const int64_t period = int64_t(config_.distractors.refine_every_epochs) * int64_t(data_.train.size());
  return seeding_allowed(config_, step_, period);
}

int64_t Trainer::seed_if_due(int view, const Camera& cam, const FloatImage& target) {
  if (view_seed_due.empty() || !view_seed_due[view]) return 0;
  view_seed_due[view] = 0;
  const DistractorSettings& ds = config_.distractors;
  TrainableGaussians& d = distractors_[view];
  const Camera& full = data_.train[view].camera;
  const int64_t full_pixels = int64_t(full.width) * full.height;
  if (!seeding_settled()) return 0;
  // This step's residual decides again: the flag was set up to an epoch ago.
  int64_t count = 0;
  if (ds.reseed_starved_views && distractor_buffer_starved(d.size(), view_static_unexplained[view], full_pixels)) {
    // As many as the growth cap allows (its A, or 4 px per distractor without one), at most
    // the view's initial K.
    DistractorSettings capped = ds;
    if (capped.pixels_per_distractor <= 0) capped.pixels_per_distractor = 4;
    const int64_t wanted = distractor_cap(view_static_unexplained[view], full_pixels, capped);
    count = std::min<int64_t>(distractor_count_for(full, ds), wanted) - int64_t(d.size());
  } else if (ds.seed_uncovered) {
    count = uncovered_seed_count(d.size(), view_static_unexplained[view], view_composite_unexplained[view],
                                 full_pixels, ds);
  }
  if (count <= 0) return 0;
  erode_mask(uncovered_mask_, cam.width, cam.height);
  const GaussianSet seeds = reseed_distractors(cam, uncovered_mask_, target.pixels, size_t(count), ds, rng_());
  d.append(seeds);
  return int64_t(seeds.size());
}

// A Gaussian whose parameter or Adam moment is not finite is removed before it can
// spread NaN through the blending of its neighbours.
// Adam's update found them (TrainableGaussians::nonfinite_groups): every value it changed
// is checked there, in the same pass.
int64_t Trainer::prune_nonfinite(TrainableGaussians& gs, const std::function<std::string()>& what) {
  if (gs.nonfinite_groups.empty()) return 0;
  std::vector<uint8_t> keep(gs.size(), 1);
  int64_t bad = 0;
  for (size_t i = 0; i < gs.size(); ++i) {
    if (!gs.nonfinite_groups[i]) continue;
    keep[i] = 0, ++bad;
    std::string groups;
    for (int g = 0; g < kParamGroups; ++g)
      if (gs.nonfinite_groups[i] >> g & 1) groups += std::string(groups.empty() ? "" : ", ") + kParamGroupTable[g].name;
    warn("step " + std::to_string(step_) + ": " + what() + " " + std::to_string(i) +
         " has a non-finite parameter or optimizer moment (" + groups + "); pruned");
  }
  gs.nonfinite_groups.clear();
  gs.keep(keep);
  return bad;
}

FloatImage Trainer::render(const Camera& camera, const std::array<float, 3>& background, const ViewLook& look) const {
  LayerPass pass;
  const bool recolor = config_.appearance.enabled && !look.appearance.empty();
  pass.render(gaussians_, camera, raster_settings(), recolor ? &appearance_ : nullptr, look.appearance);
  if (!config_.background.enabled || look.background.empty()) return composite_over_background(pass.forward, background);
  BackgroundPass sky;
  sky.forward(background_, look.background, camera, config_.background.sh_degree_at(step_), config_.threads);
  return composite_over_background(pass.forward, sky.background());
}

const char* to_string(EvalProtocol p) {
  return p == EvalProtocol::appearance_halves ? "per-image embeddings fitted on the left half, scored on the right half"
                                               : "full image";
}

ViewLook Trainer::fit_look(const TrainView& view, std::span<const float> fit) const {
  if (!has_per_image_models()) throw std::invalid_argument("fit_look: this model has no per-image appearance or background");
  const Camera& cam = view.camera;
  const size_t pixels = size_t(cam.width) * cam.height;
  if (fit.size() != pixels) throw std::invalid_argument("fit_look: the fit mask does not match view " + view.name);
  std::vector<float> keep(fit.begin(), fit.end());
  if (!view.keep.empty())
    for (size_t p = 0; p < pixels; ++p) keep[p] *= view.keep[p];
  const FloatImage photo = to_float(view.image);
  const bool recolor = config_.appearance.enabled, sky = config_.background.enabled;
  ViewLook look = config_.appearance.test_start_from_best_look ? training_look(best_training_look(view, fit))
                                                               : mean_look();
  const bool shared = shared_embedding();
  std::vector<float> m_a(look.appearance.size(), 0.0f), v_a(m_a), m_b(look.background.size(), 0.0f), v_b(m_b);
  const RasterSettings rs = raster_settings();
  const int bg_degree = config_.background.sh_degree_at(step_);
  const AdamSettings adam;
  const AppearanceSettings& as = config_.appearance;
  LayerPass pass;
  BackgroundPass sky_pass;
  std::vector<float> composite(3 * pixels), d_composite(3 * pixels);
  auto finite = [](const std::vector<float>& g) { return std::all_of(g.begin(), g.end(), [](float x) { return std::isfinite(x); }); };
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
    const float step_size = float(as.test_lr / bc1), sqrt_bc2 = float(std::sqrt(1.0 - std::pow(double(adam.beta2), step)));
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
    const double loss = photometric_loss(img.pixels, photo.pixels, cam.width, cam.height, config_.ssim_lambda, {}, keep).loss;
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
  for (const TrainView& v : views) {
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
  return out;
}

}  // namespace desplat
