// The static layer's densification rules of docs/METHOD.md §7, each on a hand-computed case:
// gradient statistics, the split rule, inherited moments and the growth budget.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>

#include "desplat/train/density.hpp"
#include "desplat/train/distractors.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/trainer.hpp"
#include "desplat/train/view_residual.hpp"
#include "support/expect.hpp"
#include "support/projection.hpp"
#include "support/synthetic_views.hpp"

namespace desplat {
namespace {

float logit(float p) { return std::log(p / (1 - p)); }

// n Gaussians of one world scale and opacity 0.5, with zero statistics.
TrainableGaussians gaussians(size_t n, float scale) {
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(n);
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = float(i), g.log_scales[3 * i + k] = std::log(scale);
    g.quats[4 * i] = 1;
    g.opacity_logits[i] = logit(0.5f);
  }
  return TrainableGaussians(g);
}

// A forward output in which Gaussian i is visible with per-axis radius radii[i] and
// conic (a, b, c); gradients absgrad[i].
struct FakeStep {
  RasterOutput fw;
  RasterGradients grads;
};
FakeStep fake_step(int size, const std::vector<uint8_t>& visible, const std::vector<float>& absgrad) {
  FakeStep s;
  s.fw.width = s.fw.height = size;
  s.fw.visible = visible;
  s.fw.radii.assign(2 * visible.size(), 2);
  s.fw.conics.assign(3 * visible.size(), 1.0f);
  for (size_t i = 0; i < visible.size(); ++i) s.fw.conics[3 * i + 1] = 0.0f;
  s.grads.absgrad = absgrad;
  return s;
}

TEST(StatisticsRules, EachStepNormalizedAtItsOwnResolution) {
  // Step 1 at 100 px with |g| = 0.002, step 2 at 200 px with |g| = 0.001.
  StatisticsRules per_step;
  per_step.normalize_each_step = true;
  TrainableGaussians a = gaussians(1, 0.01f), b = gaussians(1, 0.01f);
  const FakeStep s1 = fake_step(100, {1}, {0.002f}), s2 = fake_step(200, {1}, {0.001f});
  a.accumulate_statistics(s1.fw, s1.grads, per_step);
  a.accumulate_statistics(s2.fw, s2.grads, per_step);
  // (0.002·50 + 0.001·100) / 2 = 0.1 whatever the refinement's image size.
  EXPECT_NEAR(a.mean_gradient(0, per_step, 200), 0.1f, 1e-6f);
  EXPECT_NEAR(a.mean_gradient(0, per_step, 50), 0.1f, 1e-6f);
  // Authors: (0.003 / 2) · 0.5 · 200 = 0.15 when judged at 200 px: the 100 px step counts double.
  StatisticsRules authors;
  authors.normalize_each_step = false;
  b.accumulate_statistics(s1.fw, s1.grads, authors);
  b.accumulate_statistics(s2.fw, s2.grads, authors);
  EXPECT_NEAR(b.mean_gradient(0, authors, 200), 0.15f, 1e-6f);
}

TEST(StatisticsRules, AViewScaleMultipliesThatStepsGradientOnly) {
  // Step 1 (100 px, |g| = 0.002) judged per seen pixel with scale 2, step 2 (100 px, |g| =
  // 0.001) with 1: (0.002·2·50 + 0.001·50) / 2 = 0.125; the visible count is not scaled.
  TrainableGaussians a = gaussians(1, 0.01f);
  const FakeStep s1 = fake_step(100, {1}, {0.002f}), s2 = fake_step(100, {1}, {0.001f});
  a.accumulate_statistics(s1.fw, s1.grads, StatisticsRules{}, 2.0f);
  a.accumulate_statistics(s2.fw, s2.grads, StatisticsRules{});
  EXPECT_NEAR(a.mean_gradient(0, StatisticsRules{}, 100), 0.125f, 1e-6f);
  EXPECT_EQ(a.visible_count[0], 2);
}

TEST(StatisticsRules, VisibleCountFromOneOrSplatfactosFirstStep) {
  // Gaussian 0 visible in both steps, 1 only in the second, 2 in neither.
  const FakeStep s1 = fake_step(10, {1, 0, 0}, {1, 0, 0}), s2 = fake_step(10, {1, 1, 0}, {1, 1, 0});
  StatisticsRules from_one;
  from_one.visible_count_from_one = true;
  TrainableGaussians a = gaussians(3, 0.01f), b = gaussians(3, 0.01f);
  from_one.normalize_each_step = false;
  for (const FakeStep* s : {&s1, &s2}) a.accumulate_statistics(s->fw, s->grads, from_one);
  EXPECT_EQ(a.visible_count, (std::vector<int32_t>{3, 2, 1}));  // 1 + visible steps
  StatisticsRules splatfacto;
  splatfacto.normalize_each_step = false;
  for (const FakeStep* s : {&s1, &s2}) b.accumulate_statistics(s->fw, s->grads, splatfacto);
  EXPECT_EQ(b.visible_count, (std::vector<int32_t>{2, 2, 1}));  // first step counts all once
  EXPECT_EQ(a.absgrad_sum, b.absgrad_sum);
}

TEST(StatisticsRules, ScreenRadiusFromTheLargestEigenvalue) {
  // 2D covariance [[4, 0], [0, 1]] rotated by 45°: [[2.5, 1.5], [1.5, 2.5]]; its inverse (the
  // conic) is [[2.5, −1.5], [−1.5, 2.5]] / 4. λmax = 4 → 3·√4 = 6 px; per-axis radii say 7.
  FakeStep s = fake_step(100, {1}, {0.0f});
  s.fw.conics = {2.5f / 4, -1.5f / 4, 2.5f / 4};
  s.fw.radii = {7, 7};
  StatisticsRules eigen;
  eigen.radius_from_eigenvalue = true;
  TrainableGaussians a = gaussians(1, 0.01f), b = gaussians(1, 0.01f);
  a.accumulate_statistics(s.fw, s.grads, eigen);
  b.accumulate_statistics(s.fw, s.grads, StatisticsRules{});
  EXPECT_FLOAT_EQ(a.max_screen_radius[0], 0.06f);
  EXPECT_FLOAT_EQ(b.max_screen_radius[0], 0.07f);
}

// Gaussian with mean gradient `grad` (threshold units; 4 steps, each normalized by its own
// image size as the default StatisticsRules do) and screen size.
void set_stats(TrainableGaussians& t, size_t i, float grad, float screen) {
  t.visible_count[i] = 4;
  t.absgrad_sum[i] = grad * 4;
  t.max_screen_radius[i] = screen;
  t.statistics_empty = false;
}

TEST(DensityRules, AuthorsSplitLargeOnScreenWhateverTheGradient) {
  DensifySettings ours, authors;
  authors.split_screen_needs_grad = false;
  for (const auto& [settings, want_split] : {std::pair{ours, 0}, std::pair{authors, 1}}) {
    TrainableGaussians t = gaussians(1, 0.005f);
    set_stats(t, 0, 0.0001f, 0.06f);  // low gradient, 6 % of the image on screen
    std::mt19937_64 rng(1);
    const RefineReport r = apply_density_control(t, settings, 1000, 100, true, false, rng);
    EXPECT_EQ(r.split, want_split);
    EXPECT_EQ(r.duplicated, 0);
    EXPECT_EQ(t.size(), want_split ? 2u : 1u);
  }
  // After stop_screen_size_at the screen rule is off for both.
  TrainableGaussians t = gaussians(1, 0.005f);
  set_stats(t, 0, 0.0001f, 0.06f);
  std::mt19937_64 rng(1);
  EXPECT_EQ(apply_density_control(t, authors, 4000, 100, true, false, rng).split, 0);
}

TEST(DensityRules, CopiesInheritTheirParentsMomentsWhenAsked) {
  for (const bool inherit : {false, true}) {
    DensifySettings s;
    s.inherit_moments = inherit;
    TrainableGaussians t = gaussians(2, 0.005f);  // small: a high gradient duplicates
    set_stats(t, 0, 0.002f, 0.01f);
    set_stats(t, 1, 0.0001f, 0.01f);
    for (int g = 0; g < kParamGroups; ++g) {
      const int w = t.floats_per_gaussian(ParamGroup(g));
      for (int k = 0; k < w; ++k) t.adam_m[g][k] = 3.0f, t.adam_v[g][k] = 5.0f, t.adam_m[g][w + k] = 7.0f;
    }
    std::mt19937_64 rng(1);
    ASSERT_EQ(apply_density_control(t, s, 1000, 100, true, false, rng).duplicated, 1);
    ASSERT_EQ(t.size(), 3u);  // the two originals, then the copy of Gaussian 0
    EXPECT_EQ(t.adam_m[0][6], inherit ? 3.0f : 0.0f);
    EXPECT_EQ(t.adam_v[0][6], inherit ? 5.0f : 0.0f);
    EXPECT_EQ(t.adam_m[0][3], 7.0f);  // the originals keep theirs
  }
}

TEST(DensityRules, GrowthBudgetTakesTheHighestGradientsFirst) {
  // Four small Gaussians, three with a high gradient (2.5×, 5×, 3× the threshold): each
  // duplicate adds one; a budget of 2 takes Gaussians 1 and 2.
  DensifySettings s;
  TrainableGaussians t = gaussians(4, 0.005f);
  const float thr = s.grad_threshold;
  set_stats(t, 0, 2.5f * thr, 0.01f);
  set_stats(t, 1, 5 * thr, 0.01f);
  set_stats(t, 2, 3 * thr, 0.01f);
  set_stats(t, 3, 0.1f * thr, 0.01f);
  std::mt19937_64 rng(1);
  const RefineReport r = apply_density_control(t, s, 1000, 100, true, false, rng, 2);
  EXPECT_EQ(r.high_gradient, 3);
  EXPECT_EQ(r.duplicated, 2);
  EXPECT_EQ(r.held_back, 1);
  ASSERT_EQ(t.size(), 6u);
  EXPECT_EQ(t.params.means[3 * 4], 1.0f);  // copies of Gaussians 1 and 2, in row order
  EXPECT_EQ(t.params.means[3 * 5], 2.0f);
  // Bins [0, ½), [½, 1), [1, 2), [2, 4), [4, ∞) of mean gradient / threshold.
  EXPECT_EQ(r.gradient_ratio_bins, (std::array<int64_t, kGradientRatioBins>{1, 0, 0, 2, 1}));
  // A budget of zero: nothing added; no budget: all three.
  TrainableGaussians u = gaussians(4, 0.005f);
  for (size_t i = 0; i < 3; ++i) set_stats(u, i, 2 * thr, 0.01f);
  std::mt19937_64 rng2(1);
  EXPECT_EQ(apply_density_control(u, s, 1000, 100, true, false, rng2, 0).held_back, 3);
  EXPECT_EQ(u.size(), 4u);
}

}  // namespace
}  // namespace desplat
