// The trainer's state and the training step: a batch of views (one by default), each view's
// pass (trainer_view_pass.cpp), the static buffer's Adam step and density control, then the
// distractors' growth (trainer_distractor_growth.cpp) (docs/METHOD.md §4–7).
#include "desplat/train/trainer.hpp"

#include <omp.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <stdexcept>

#include "desplat/train/background.hpp"
#include "desplat/train/batch.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/init.hpp"
#include "desplat/train/loss.hpp"

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

Trainer::Trainer(const TrainingData& data, TrainConfig config, Communicator* comm)
    : data_(data),
      config_(std::move(config)),
      comm_(comm && comm->size() > 1 ? comm : nullptr),
      rank_(comm_ ? comm_->rank() : 0),
      ranks_(comm_ ? comm_->size() : 1),
      rng_(config_.seed) {
  // Adam, the loss and the initialization are plain `omp parallel` loops: without this a
  // --threads 1 run would still start a team per core (and spin in it).
  if (config_.threads > 0) omp_set_num_threads(config_.threads);
  if (data_.train.empty()) throw std::invalid_argument("training needs at least one training view");
  // A batch holds at most one step of the refinement schedule (batch_event).
  if (config_.batch < 1 || config_.batch > std::max(1, config_.densify.refine_every))
    throw std::invalid_argument("batch " + std::to_string(config_.batch) + " must be 1.." +
                                std::to_string(std::max(1, config_.densify.refine_every)) +
                                " (at most densify.refine_every views per step); use a smaller --batch");
  // The per-image models' shared networks take one update per view, in order: that sequence
  // does not divide between ranks (docs/METHOD.md §6, ranks).
  if (ranks_ > 1 && (config_.appearance.enabled || config_.background.enabled))
    throw std::invalid_argument(
        "the appearance and background models train in one process only, and this job has " + std::to_string(ranks_) +
        " ranks: run it without mpirun/srun, or choose the effects without them (--effects distractors or "
        "--static-only)");
  for (size_t i = 0; i < data_.train.size(); ++i) {
    const TrainView& v = data_.train[i];
    v.camera.validate();
    if (!owns_view(i)) continue;  // another rank holds its photo
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
        throw std::invalid_argument("view " + v.name +
                                    ": its mask keeps no pixel (it is all black), so the view has "
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
    throw std::invalid_argument(std::string(kind) + " view " + v.name + " is " + where +
                                ": the SSIM loss needs at least " + std::to_string(kSsimWindow) + "x" +
                                std::to_string(kSsimWindow) + " px; use a smaller --downscale" +
                                (factor > 1 ? " or a lower num_downscales" : ""));
  };
  for (const TrainView& v : data_.train) check_size(v, coarsest, "training");
  for (const TrainView& v : data_.test) check_size(v, 1, "test");
  config_ = effective_config(std::move(config_), data_);
  std::vector<uint8_t> transient;
  if (config_.transient_points.action != TransientPointAction::keep) {
    transient = transient_points(data_, config_.transient_points, comm_);
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
      scene_depth_ =
          camera_path_.median_depth > 0 ? camera_path_.median_depth : median_scene_depth(cameras, data_.points);
  }
  if (config_.distractors.enabled) {
    std::vector<Camera> cameras;
    for (const TrainView& v : data_.train) cameras.push_back(v.camera);
    check_initial_distractors(cameras, config_.distractors);
    distractors_.reserve(data_.train.size());
    for (const TrainView& v : data_.train)
      distractors_.emplace_back(init_distractors(v.camera, config_.distractors, rng_()));
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
  keep_own_share();
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

RasterSettings Trainer::raster_settings() const { return raster_settings_at(step_); }

RasterSettings Trainer::raster_settings_at(int64_t index) const {
  RasterSettings rs;
  rs.num_threads = config_.threads;
  rs.isa = config_.kernel_isa;
  rs.active_sh_degree = config_.sh_degree_at(index);
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

float Trainer::means_lr_at(int64_t index) const {
  const double progress = std::min(1.0, double(index) / double(std::max<int64_t>(1, config_.means_lr_decay_steps)));
  return float(std::exp(std::log(config_.lr.means) * (1 - progress) + std::log(config_.means_lr_final) * progress));
}

const std::vector<uint8_t>& Trainer::uncovered_mask() const {
  static const std::vector<uint8_t> none;
  return batch_views_.empty() ? none : batch_views_.back().uncovered;
}

// A step over a batch (docs/METHOD.md §6, batches): each view's pass in draw order, then the
// static buffer's one update, then each view's seeding, then every view's distractor
// refinement when its schedule falls in the batch. With one view this is the single-view
// step in the same order of random draws.
StepStats Trainer::step() {
  StepStats stats;
  stats.step = step_;
  const int64_t left = config_.iterations - step_;
  const int views = int(left > 0 ? std::min<int64_t>(config_.batch, left) : config_.batch);
  stats.views = views;
  batch_views_.resize(size_t(views));
  StepProfiler profile;
  const CommTotals comm_before = comm_ ? comm_->totals() : CommTotals{};
  bool first = true;                  // the first of the batch's views this rank holds starts the sums
  std::vector<int> held, held_views;  // the batch's positions and views this rank trained
  for (int b = 0; b < views; ++b) {
    batch_views_[size_t(b)].index = step_ + b;
    if (train_view(batch_views_[size_t(b)], first, profile, stats)) {
      first = false;
      held.push_back(b), held_views.push_back(batch_views_[size_t(b)].view);
    }
  }
  // The static gradients in the view tree's order, the same floats in the same order in one
  // process and over a power-of-two number of ranks (docs/METHOD.md §6, ranks).
  profile.time(&StepTimings::optimizer, [&] {
    const int root = sum_in_view_tree(held_views, [&](int into, int from) {
      add_gradients(batch_views_[size_t(held[size_t(into)])].grads, batch_views_[size_t(held[size_t(from)])].grads);
    });
    if (root >= 0) std::swap(batch_grads_, batch_views_[size_t(held[size_t(root)])].grads);
  });
  if (comm_) profile.time(&StepTimings::optimizer, [&] { sum_batch_over_ranks(stats); });
  stats.loss /= views, stats.psnr /= views;
  const int64_t event = update_static(views, profile, stats);

  // Each view's seeding, then every view's refinement when it is due in this batch. A view's
  // seeding draws from the random state on its own rank; the others follow that state.
  const bool refine_distractors_now = event >= 0 && distractor_refine_due(event, static_cast<int>(data_.train.size()),
                                                                          config_.densify, config_.distractors);
  if (config_.distractors.enabled)
    for (BatchView& bv : batch_views_)
      if (view_seed_due[bv.view])
        profile.time(&StepTimings::distractor, [&] {
          if (owns_view(size_t(bv.view)))
            stats.reseeded += seed_if_due(bv);
          else
            view_seed_due[bv.view] = 0;
          if (comm_) follow_random_state(rank_of_view(size_t(bv.view), ranks_));
        });
  if (refine_distractors_now) {
    const BatchView& at = batch_views_[size_t(event - step_)];
    profile.time(&StepTimings::distractor,
                 [&] { refine_all_distractors(event, std::max(at.camera.width, at.camera.height), at.factor, stats); });
  }
  stats.timings = profile.timings;
  stats.gaussians = gaussians_.size();
  if (comm_) {
    const CommTotals after = comm_->totals();
    stats.comm_bytes = after.bytes - comm_before.bytes;
    stats.comm_seconds = after.seconds - comm_before.seconds;
  }
  step_ += views;
  return stats;
}

int64_t Trainer::update_static(int views, StepProfiler& profile, StepStats& stats) {
  const int64_t last = step_ + views - 1;
  const int64_t event = batch_event(step_, views, config_.densify.refine_every);
  profile.time(&StepTimings::optimizer, [&] {
    // The batch's rates at its first view (the means' decay), × √views; the colour bands of the
    // degree its last view trains.
    LearningRates lr = config_.lr;
    lr.means = means_lr_at(step_);
    lr = batch_learning_rates(lr, views);
    const int sh_bands = config_.sh_degree_at(last) + 1;
    const std::span<const uint8_t> rows =
        config_.selective_adam ? std::span<const uint8_t>(batch_visible_) : std::span<const uint8_t>();
    gaussians_.adam_update(batch_grads_, lr, AdamSettings{}, 3 * sh_bands * sh_bands, rows, views);
    stats.nonfinite_pruned += prune_nonfinite(gaussians_, last, [] { return std::string("static Gaussian"); });
    if (event < 0) return;
    // Judged at the image size of the view whose index the schedule names.
    const Camera& at = batch_views_[size_t(event - step_)].camera;
    // Every rank decides on the job's statistics with the same random state: the same decisions.
    if (comm_) reduce_static_statistics();
    stats.refine = refine_gaussians(gaussians_, config_.densify, event, std::max(at.width, at.height),
                                    static_cast<int>(data_.train.size()), rng_);
    if (comm_) keep_own_share();
    if (stats.refine.ran && !camera_path_.empty()) cull_camera_path(stats.refine);
  });
  return event;
}

// A Gaussian whose parameter or Adam moment is not finite is removed before it can
// spread NaN through the blending of its neighbours.
// Adam's update found them (TrainableGaussians::nonfinite_groups): every value it changed
// is checked there, in the same pass.
int64_t Trainer::prune_nonfinite(TrainableGaussians& gs, int64_t index, const std::function<std::string()>& what) {
  if (gs.nonfinite_groups.empty()) return 0;
  std::vector<uint8_t> keep(gs.size(), 1);
  int64_t bad = 0;
  for (size_t i = 0; i < gs.size(); ++i) {
    if (!gs.nonfinite_groups[i]) continue;
    keep[i] = 0, ++bad;
    std::string groups;
    for (int g = 0; g < kParamGroups; ++g)
      if (gs.nonfinite_groups[i] >> g & 1) groups += std::string(groups.empty() ? "" : ", ") + kParamGroupTable[g].name;
    warn("step " + std::to_string(index) + ": " + what() + " " + std::to_string(i) +
         " has a non-finite parameter or optimizer moment (" + groups + "); pruned");
  }
  gs.nonfinite_groups.clear();
  gs.keep(keep);
  return bad;
}

}  // namespace desplat
