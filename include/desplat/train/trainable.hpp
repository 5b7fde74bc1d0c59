// Gaussians under optimization: parameters, their Adam moments, and the densification
// statistics, all row-aligned (row i of every array is Gaussian i). Densification and
// pruning go through keep()/append() so no array can fall out of step with the others.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "desplat/core/gaussians.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/param_groups.hpp"

namespace desplat {

// How the densification statistics are gathered and read (docs/METHOD.md §7). Each switch
// is a departure from the authors' code with its reason in docs/METHOD.md §7; --preset paper
// sets the authors' choice.
struct StatisticsRules {
  // true: each step's gradient is scaled by 0.5·max(W, H) of that step's image, so a
  // refinement just after a resolution switch judges all its steps in the same units.
  // false (authors): the sum is scaled once, by the image size of the refinement's step.
  bool normalize_each_step = true;
  // true (authors): every Gaussian's count starts at 1 and adds 1 per step it is visible.
  // false (Splatfacto): the first step after a reset counts every Gaussian once, later
  // steps count visible ones only.
  bool visible_count_from_one = false;
  // true (authors' gsplat): screen radius 3·√λmax of the 2D covariance. false: the
  // larger of the rasterizer's per-axis extents 3.33·√Σii.
  bool radius_from_eigenvalue = false;
  // true: a static Gaussian whose projected centre lies where this step's distractor layer is
  // a mask (A_d > kDistractorMaskThreshold) does not count as seen by the view, as a centre on
  // an ignored pixel does not: its gradient there passes through 1 − A_d < ½, so counting the
  // view dilutes the mean gradient of what lies behind an occluder. false (authors): every
  // view it projects into counts, the default: the rule helps heavy synthetic clutter and hurts
  // the occluded fox (docs/BENCHMARKS.md, the defaults).
  bool hide_behind_distractors = false;
  // true: a static Gaussian's gradient from a step whose view has distractors is scaled by
  // kept pixels / Σ kept·(1 − A_d) (seen_pixel_gradient_scale): the loss is a mean over every
  // pixel, but under a distractor the static layer gets almost no gradient, so the same
  // residual on what the view still shows would read smaller than on a clean view. A user
  // mask's loss is a mean over the kept pixels only; this judges a learned mask the same way.
  // false (authors): the gradient as it is.
  bool gradient_per_seen_pixel = true;
};

// Adam hyper-parameters (docs/METHOD.md §6).
struct AdamSettings {
  float beta1 = 0.9f, beta2 = 0.999f, eps = 1e-15f;
};

// PyTorch's Adam on n contiguous values with one step size (= rate / bias correction 1) and
// sqrt_bc2 = √(bias correction 2). Returns whether any value, first or second moment ended
// non-finite. Every parameter set (Gaussians, the appearance model) updates through it.
bool adam_span(float* p, float* m, float* v, const float* g, size_t n, float step_size, float sqrt_bc2,
               const AdamSettings& a);

// One Adam step's bias corrections: bc1 = 1 − β1^t (step sizes are rate / bc1) and
// √(1 − β2^t) for adam_span, after advancing the count t by `views`: a step over a batch of
// B views counts B, so the corrections of B-view steps with β^B (batch_adam_settings) are
// those of single-view steps at the same views seen (docs/METHOD.md §6, batches).
struct AdamBiasCorrection {
  double bc1;
  float sqrt_bc2;
};
AdamBiasCorrection advance_adam_step(int64_t& step, const AdamSettings& a, int views = 1);

// The moments' decay of one step over `views` views: β1^views and β2^views, ε unchanged
// (Grendel-GS's momentum rule, docs/METHOD.md §6, batches); `a` itself when views is 1.
AdamSettings batch_adam_settings(const AdamSettings& a, int views);

// Whether every value is finite (a gradient that may enter Adam).
bool all_finite(std::span<const float> values);

struct TrainableGaussians {
  GaussianSet params;
  std::array<std::vector<float>, kParamGroups> adam_m, adam_v;  // same shapes as params
  int64_t adam_step = 0;  // Adam's bias-correction count in views seen (one for all groups)
  // Densification statistics since the last refinement (docs/METHOD.md §7).
  std::vector<float> absgrad_sum;        // [N] Σ over steps of the absgrad statistic
  std::vector<int32_t> visible_count;    // [N] steps in which the Gaussian was visible
  std::vector<float> max_screen_radius;  // [N] max over steps of radius / max(W, H)
  bool statistics_empty = true;          // no step recorded since the last reset

  explicit TrainableGaussians(GaussianSet initial = {});
  size_t size() const { return params.size(); }
  std::vector<float>& param(ParamGroup g) { return params.*param_group(g).values; }
  const std::vector<float>& param(ParamGroup g) const { return params.*param_group(g).values; }
  int floats_per_gaussian(ParamGroup g) const;

  // Keeps the rows where keep[i] != 0, in order, in every array.
  void keep(const std::vector<uint8_t>& keep);
  // Appends Gaussians (same color mode and SH degree) with zero moments and statistics.
  void append(const GaussianSet& extra);
  // Row `dst` takes row `src`'s Adam moments (a densified copy continuing its parent's).
  void copy_moments(size_t dst, size_t src);
  void reset_statistics();
  // Records one step's statistics from the rasterizer's outputs for this view; each
  // gradient is multiplied by `view_scale` (seen_pixel_gradient_scale, or 1).
  void accumulate_statistics(const RasterOutput& forward, const RasterGradients& grads,
                             const StatisticsRules& rules = {}, float view_scale = 1.0f);
  // Gaussian i's mean gradient since the last reset in the units of the densification
  // threshold; `image_size` = max(W, H) of the refinement step's image (used when the
  // rules normalize at the refinement). 0 when it was never counted.
  float mean_gradient(size_t i, const StatisticsRules& rules, int image_size) const;

  // One Adam step (PyTorch's formulation) over every group with the given rates. In SH
  // colour mode only the first `trained_color_floats` floats of each colour row are updated
  // (3·(d+1)² for active degree d; −1: all): the bands above the active degree have zero
  // gradient and zero moments, so Adam would leave them unchanged anyway. Afterwards
  // `nonfinite_groups` names the rows that went non-finite (see below).
  // `rows` (empty: every row) selects the Gaussians to update, one flag per row: a row whose
  // flag is 0 keeps its parameters and both moments exactly as they are, as if the step had
  // not happened for it; the step count, and so the bias correction, advances for all
  // (selective Adam, docs/METHOD.md §6).
  // `views` > 1: `grads` is the sum over a batch of that many views; the moments decay with
  // batch_adam_settings and the bias correction counts views (the caller scales the rates).
  void adam_update(const RasterGradients& grads, const LearningRates& lr, const AdamSettings& adam = {},
                   int trained_color_floats = -1, std::span<const uint8_t> rows = {}, int views = 1);
  // After adam_update: empty when every updated value and moment is finite; otherwise [N],
  // bit g set when row i of group g holds a non-finite value or moment.
  std::vector<uint8_t> nonfinite_groups;
  // Throws std::logic_error if any array's length disagrees with size().
  void check_consistent() const;
};

}  // namespace desplat
