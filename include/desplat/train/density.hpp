// Adaptive density control for static Gaussians (docs/METHOD.md §7, Splatfacto defaults).
// Thresholds are in the normalized world frame (§1) and in screen fractions.
#pragma once

#include <array>
#include <cstdint>
#include <random>

#include "desplat/train/free_space.hpp"
#include "desplat/train/trainable.hpp"

namespace desplat {

struct DensifySettings {
  int warmup = 500;            // no refinement at or before this step
  int refine_every = 100;      // refine at steps that are multiples of this
  int reset_alpha_every = 30;  // opacity reset every reset_alpha_every·refine_every steps
  int stop_split_at = 15000;   // densify and reset only before this step; cull after
  int stop_screen_size_at = 4000;
  float grad_threshold = 0.0008f;   // mean absgrad (× 0.5·max(W, H)) that counts as high
  float size_threshold = 0.01f;     // max world scale: split above, duplicate at or below
  float split_screen_size = 0.05f;  // also split large-on-screen Gaussians before stop_screen_size_at
  int split_samples = 2;
  float split_scale_factor = 1.6f;
  float cull_alpha = 0.1f;         // cull opacity below this
  float cull_scale = 0.5f;         // after the first reset: cull max world scale above this
  float cull_screen_size = 0.15f;  // … or screen size above this before stop_screen_size_at
  bool enabled = true;
  // Departures from the authors' code, each with its reason in docs/METHOD.md §7 (--preset
  // paper sets the authors' side of each):
  StatisticsRules stats;
  // true: a large-on-screen Gaussian is split only if its gradient is high too. false
  // (authors): before stop_screen_size_at it is split whatever its gradient.
  bool split_screen_needs_grad = true;
  // true: a split or duplicated copy starts with its parent's Adam moments. false
  // (authors): zero moments, which with a mature bias correction make its first steps
  // about 3× the learning rate.
  bool inherit_moments = false;
  // Ours: at each refinement also cull static Gaussians on the camera path (free_space.hpp);
  // radius 0 (--preset paper) turns it off.
  CameraPathSettings camera_path;
};

// The distribution of mean gradient / threshold at a refinement, in bins
// [0, ½), [½, 1), [1, 2), [2, 4), [4, ∞): the last three are the high-gradient ones.
constexpr int kGradientRatioBins = 5;

struct RefineReport {
  int64_t split = 0, duplicated = 0, culled = 0;
  int64_t high_gradient = 0;   // candidates for densification (mean gradient > threshold)
  int64_t held_back = 0;       // candidates not densified because of a growth budget
  int64_t on_camera_path = 0;  // culled for lying on the camera path (counted in culled too)
  std::array<int64_t, kGradientRatioBins> gradient_ratio_bins{};
  bool opacity_reset = false;
  bool ran = false;
  RefineReport& operator+=(const RefineReport& r);
};

// No limit on how many Gaussians a refinement may add.
constexpr int64_t kUnlimitedGrowth = -1;

// Called after every optimizer step. `step` counts from 0; `image_size` is max(W, H)
// of the training images at this step; `num_train_views` is the number of training
// views. Clears the statistics after each refinement.
RefineReport refine_gaussians(TrainableGaussians& g, const DensifySettings& s, int64_t step, int image_size,
                              int num_train_views, std::mt19937_64& rng);

// Whether refine_gaussians resets the static opacities after step `step`: at the first
// refinement of every reset_alpha_every·refine_every steps, after the warm-up and before
// stop_split_at.
bool opacity_reset_due(const DensifySettings& s, int64_t step);

// One refinement regardless of the schedule: densify (split/duplicate) when `densify`,
// then cull (opacity, and the scale/screen-size rules by `step`); with `cull_unseen`
// also every Gaussian not seen since the last refinement (zero max screen radius: the
// per-view distractor rule of docs/METHOD.md §7). No opacity reset. Clears the statistics.
// `max_new` ≥ 0 caps the Gaussians densification adds (each split or duplicate adds one
// with split_samples = 2): the candidates with the highest mean gradient go first.
RefineReport apply_density_control(TrainableGaussians& g, const DensifySettings& s, int64_t step, int image_size,
                                   bool densify, bool cull_unseen, std::mt19937_64& rng,
                                   int64_t max_new = kUnlimitedGrowth);

// Gaussian-wise pieces, exposed for tests.
GaussianSet split_samples(const GaussianSet& g, const std::vector<uint8_t>& mask, int samples, float scale_factor,
                          std::mt19937_64& rng);
GaussianSet copy_rows(const GaussianSet& g, const std::vector<uint8_t>& mask);

}  // namespace desplat
