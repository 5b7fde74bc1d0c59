// Distractor growth across views (docs/METHOD.md §7, growth control): every view's
// refinement, the seeding rules and their schedule, and the static statistics' view rules.
#include "desplat/train/trainer.hpp"

#include <algorithm>

#include "desplat/train/mask_coherence.hpp"
#include "desplat/train/view_residual.hpp"

namespace desplat {

void Trainer::refine_all_distractors(int64_t index, int image_size, int factor, StepStats& stats) {
  stats.distractor_refine.ran = true;
  const DistractorSettings& ds = config_.distractors;
  // In view order; a view's refinement draws from the random state on its own rank, and the
  // other ranks follow that state before the next view's.
  for (size_t v = 0; v < distractors_.size(); ++v) {
    if (!owns_view(v)) {
      follow_random_state(rank_of_view(v, ranks_));
      continue;
    }
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
      r.report = refine_distractors(d, config_.densify, ds, index, image_size, rng_, r.budget, scene_depth_);
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
    const bool starved =
        ds.reseed_starved_views && distractor_buffer_starved(d.size(), view_static_unexplained[v], pixels);
    const bool uncovered = ds.seed_uncovered && uncovered_seed_count(d.size(), view_static_unexplained[v],
                                                                     view_composite_unexplained[v], pixels, ds) > 0;
    view_seed_due[v] = index < config_.densify.stop_split_at && seeding_settled(index) && (starved || uncovered);
    if (comm_) follow_random_state(rank_);
  }
  // Every rank learns which views seed at their next step (Trainer::step).
  if (comm_) share_view_values();
}

void Trainer::seed_from_transient_points(const std::vector<uint8_t>& transient) {
  // One distractor on the pixel each transient point projects to, in every training view
  // that observes it: the same seeds the growth rules place on uncovered pixels.
  for (size_t v = 0; v < data_.train.size(); ++v) {
    // On the view's own rank, the others following its random state (as refine_all_distractors).
    if (comm_ && !owns_view(v)) {
      follow_random_state(rank_of_view(v, ranks_));
      continue;
    }
    seed_view_from_transient_points(v, transient);
    if (comm_) follow_random_state(rank_);
  }
  if (comm_) comm_->sum(std::span<int64_t>(&transient_seeded, 1));
}

void Trainer::seed_view_from_transient_points(size_t v, const std::vector<uint8_t>& transient) {
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
  if (count == 0) return;
  const GaussianSet seeds =
      reseed_distractors(c, mask, to_float(view.image).pixels, count, config_.distractors, rng_());
  distractors_[v].append(seeds);
  transient_seeded += int64_t(seeds.size());
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

bool Trainer::seeding_settled(int64_t index) const {
  const int64_t period = int64_t(config_.distractors.refine_every_epochs) * int64_t(data_.train.size());
  return seeding_allowed(config_, index, period);
}

int64_t Trainer::seed_if_due(BatchView& bv) {
  const int view = bv.view;
  const Camera& cam = bv.camera;
  if (view_seed_due.empty() || !view_seed_due[view]) return 0;
  view_seed_due[view] = 0;
  const DistractorSettings& ds = config_.distractors;
  TrainableGaussians& d = distractors_[view];
  const Camera& full = data_.train[view].camera;
  const int64_t full_pixels = int64_t(full.width) * full.height;
  if (!seeding_settled(bv.index)) return 0;
  // This pass's residual decides again: the flag was set up to an epoch ago.
  int64_t count = 0;
  if (ds.reseed_starved_views && distractor_buffer_starved(d.size(), view_static_unexplained[view], full_pixels)) {
    // As many as the growth cap allows (its A, or 4 px per distractor without one), at most
    // the view's initial K.
    DistractorSettings capped = ds;
    if (capped.pixels_per_distractor <= 0) capped.pixels_per_distractor = 4;
    const int64_t wanted = distractor_cap(view_static_unexplained[view], full_pixels, capped);
    count = std::min<int64_t>(distractor_count_for(full, ds), wanted) - int64_t(d.size());
  } else if (ds.seed_uncovered) {
    count = uncovered_seed_count(d.size(), view_static_unexplained[view], view_composite_unexplained[view], full_pixels,
                                 ds);
  }
  if (count <= 0) return 0;
  erode_mask(bv.uncovered, cam.width, cam.height);
  const FloatImage& target = target_at(view, bv.factor);
  const GaussianSet seeds = reseed_distractors(cam, bv.uncovered, target.pixels, size_t(count), ds, rng_());
  d.append(seeds);
  return int64_t(seeds.size());
}

}  // namespace desplat
