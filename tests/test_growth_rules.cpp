// The densification switches and distractor growth rules of docs/METHOD.md §7–8, each on a
// hand-computed case: gradient statistics, the split rule, inherited moments, the growth
// budget, starved buffers and their re-seeding, the explained-pixel penalty and the presets.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>

#include "desplat/train/density.hpp"
#include "desplat/train/distractors.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/view_residual.hpp"
#include "desplat/train/trainer.hpp"
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

using test::project_mean;

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

TEST(DistractorGrowth, CapIsUnexplainedPixelsPerDistractor) {
  DistractorSettings s;
  s.pixels_per_distractor = 0;
  EXPECT_EQ(distractor_growth_budget(100, 0.1, 10000, s), kUnlimitedGrowth);  // off at 0 (paper)
  s.pixels_per_distractor = 16;
  EXPECT_EQ(distractor_cap(0.1, 10000, s), 62);             // 1,000 px / 16
  EXPECT_EQ(distractor_growth_budget(50, 0.1, 10000, s), 12);
  EXPECT_EQ(distractor_growth_budget(80, 0.1, 10000, s), 0);  // over the cap: no growth (no forced shrink)
  EXPECT_EQ(distractor_growth_budget(0, 0.0, 10000, s), 0);
  EXPECT_EQ(distractor_cap(2.0, 160, s), 10);                // fraction clamped to 1
}

TEST(DistractorGrowth, StarvedBufferRule) {
  // 10,000 px, 5 % unexplained = 500 px: starved below 500 / 256 ≈ 1.95 distractors.
  EXPECT_TRUE(distractor_buffer_starved(0, 0.05, 10000));
  EXPECT_TRUE(distractor_buffer_starved(1, 0.05, 10000));
  EXPECT_FALSE(distractor_buffer_starved(2, 0.05, 10000));
  EXPECT_FALSE(distractor_buffer_starved(0, 0.005, 10000));  // under 1 % of the frame: nothing to do
}

TEST(DistractorGrowth, UncoveredSeedCountIsOnePerAPixelsUnderTheCap) {
  // 10,000 px at full resolution, A = 4: static leaves 20 % unexplained → cap 500.
  DistractorSettings s;
  s.pixels_per_distractor = 4;
  EXPECT_EQ(uncovered_seed_count(100, 0.2, 0.1, 10000, s), 250);  // 1,000 uncovered px / 4
  EXPECT_EQ(uncovered_seed_count(300, 0.2, 0.1, 10000, s), 200);  // only the cap's room
  EXPECT_EQ(uncovered_seed_count(600, 0.2, 0.1, 10000, s), 0);    // over the cap
  EXPECT_EQ(uncovered_seed_count(0, 0.2, 0.01, 10000, s), 0);     // 1 % or less: fitting error
  EXPECT_EQ(uncovered_seed_count(0, 0.2, 0.011, 10000, s), 27);   // 110 px / 4, rounded down
  s.pixels_per_distractor = 0;                                    // no cap: 4 px each, unbounded room
  EXPECT_EQ(uncovered_seed_count(1000000, 0.2, 0.1, 10000, s), 250);
}

// Round distractors in front of an identity camera: world (x, y, z) with world scale `scale`
// and opacity o, so each is a disc of σ = f·scale/z px on screen.
GaussianSet round_distractors(const std::vector<std::array<float, 5>>& xyz_scale_opacity) {
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(xyz_scale_opacity.size());
  for (size_t i = 0; i < g.size(); ++i) {
    const auto& d = xyz_scale_opacity[i];
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = d[k], g.log_scales[3 * i + k] = std::log(d[3]);
    g.quats[4 * i] = 1;
    g.opacity_logits[i] = logit(d[4]);
    for (int c = 0; c < 3; ++c) g.colors[3 * i + c] = 0.5f;
  }
  return g;
}

Camera identity_camera(int size, float focal) {
  Camera cam;
  cam.width = cam.height = size;
  cam.fx = cam.fy = focal;
  cam.cx = cam.cy = size * 0.5f;
  return cam;
}

TEST(DistractorGrowth, IdleCullRemovesDistractorsHiddenOrOffScreenAndKeepsVisibleOnes) {
  // 64×64 px, f = 100, threshold 1 px. A: a 20 px opaque disc at the centre, in front.
  // B: a 2 px disc (o = 0.5) right behind A, where A's T ≤ 1 − 0.999·e^(−6²/(2·20²)) ≈ 0.045,
  // so B's weight is ≤ 0.045 · 2π·4.3·0.5 ≈ 0.6 px (alone it would be ≈ 13.4 px).
  // C: behind the camera (weight 0). D: a 3 px disc (o = 0.5) at A's depth, 34 px from the
  // centre, where A's α is 0.999·e^(−34²/(2·20²)) ≈ 0.24: 2π·(9 + 0.3)·(0.5 − 1/255) ≈ 29 px
  // if drawn before A, about 0.76 of that (≈ 22 px) if after: kept either way.
  TrainableGaussians g(round_distractors({{0.0f, 0.0f, 1.0f, 0.2f, 0.9999f},
                                          {0.0f, 0.0f, 2.0f, 0.04f, 0.5f},
                                          {0.0f, 0.0f, -1.0f, 0.05f, 0.9f},
                                          {0.24f, 0.24f, 1.0f, 0.03f, 0.5f}}));
  DistractorSettings s;
  s.min_blend_weight = 1.0f;
  EXPECT_EQ(cull_idle_distractors(g, identity_camera(64, 100), 1, s), 2);
  ASSERT_EQ(g.size(), 2u);
  EXPECT_FLOAT_EQ(g.params.means[2], 1.0f);   // A
  EXPECT_FLOAT_EQ(g.params.means[3], 0.24f);  // D
  // Off (the paper's setting): nothing is removed, whatever the weights.
  TrainableGaussians h(round_distractors({{0.0f, 0.0f, -1.0f, 0.05f, 0.9f}}));
  s.min_blend_weight = 0.0f;
  EXPECT_EQ(cull_idle_distractors(h, identity_camera(64, 100), 1, s), 0);
  EXPECT_EQ(h.size(), 1u);
}

TEST(DistractorGrowth, IdleCullCountsPixelsAtFullTrainingResolution) {
  // A 1.5 px disc on a half-size camera: 2π·(1.5² + 0.3)·(0.5 − 1/255) ≈ 7.95 px there,
  // ≈ 31.8 px of the full-size view. With a threshold of 20 px it stays when the camera is the
  // view at factor 2 and goes when the same camera is taken as full size.
  DistractorSettings s;
  s.min_blend_weight = 20.0f;
  TrainableGaussians at_half(round_distractors({{0.0f, 0.0f, 1.0f, 0.03f, 0.5f}}));
  EXPECT_EQ(cull_idle_distractors(at_half, identity_camera(32, 50), 2, s), 0);
  TrainableGaussians as_full(round_distractors({{0.0f, 0.0f, 1.0f, 0.03f, 0.5f}}));
  EXPECT_EQ(cull_idle_distractors(as_full, identity_camera(32, 50), 1, s), 1);
  EXPECT_EQ(as_full.size(), 0u);
}

TEST(DistractorGrowth, AlphaSumIsEachDistractorsAlphaIntegratedOverTheImage) {
  // 64×64 px, f = 100, a round Gaussian of world scale s at depth z on the optical axis has
  // σ = f·s/z px, plus the rasterizer's 0.3 px² blur: ∫α = o·2π·(σ² + 0.3).
  // A: z 1, s 0.1, o 0.5 → 0.5·2π·100.3 ≈ 315.09. B: straight behind A (layers count whatever
  // covers them), z 2, s 0.1, o 0.8 → 0.8·2π·25.3 ≈ 127.17. C: behind the camera, 0.
  // D: z 1, s 10 (σ = 1,000 px), counted as at most the image's 4,096 px.
  const Camera camera = identity_camera(64, 100);
  const GaussianSet g = round_distractors({{0.0f, 0.0f, 1.0f, 0.1f, 0.5f},
                                           {0.0f, 0.0f, 2.0f, 0.1f, 0.8f},
                                           {0.0f, 0.0f, -1.0f, 0.1f, 0.9f}});
  const double a = 0.5 * 2 * M_PI * 100.3, b = 0.8 * 2 * M_PI * 25.3;
  EXPECT_NEAR(distractor_alpha_sum(g.view(), camera), a + b, 1e-3 * (a + b));
  const GaussianSet d = round_distractors({{0.0f, 0.0f, 1.0f, 10.0f, 0.5f}});
  EXPECT_NEAR(distractor_alpha_sum(d.view(), camera), 4096.0, 1e-6);
  EXPECT_EQ(distractor_alpha_sum(GaussianSet{}.view(), camera), 0.0);
}

TEST(DistractorGrowth, AlphaSumBudgetFillsTheLimitAtTheBuffersMeanAlpha) {
  DistractorSettings s;
  s.max_alpha_sum = 0.0f;
  EXPECT_EQ(alpha_sum_budget(100, 4000.0, 0.1, 10000, s), kUnlimitedGrowth);  // off at 0 (--preset paper)
  s.max_alpha_sum = 4.5f;  // exact in float, so the limits below are exact
  // 10 % of 10,000 px unexplained: limit 4.5 · 1,000 = 4,500. 100 distractors summing 4,000:
  // 40 each, room for ⌊500 / 40⌋ = 12 more.
  EXPECT_EQ(alpha_sum_budget(100, 4000.0, 0.1, 10000, s), 12);
  EXPECT_EQ(alpha_sum_budget(100, 4500.0, 0.1, 10000, s), 0);   // at the limit
  EXPECT_EQ(alpha_sum_budget(100, 9000.0, 0.1, 10000, s), 0);   // over it: no growth, no forced shrink
  EXPECT_EQ(alpha_sum_budget(100, 10.0, 0.0, 10000, s), 0);     // nothing unexplained
  EXPECT_EQ(alpha_sum_budget(10, 10.0, 3.0, 100, s), 440);      // fraction clamped to 1: (450 − 10) / 1
  EXPECT_EQ(alpha_sum_budget(0, 0.0, 0.1, 10000, s), kUnlimitedGrowth);  // empty: the count cap decides
}

TEST(ViewResidual, ErosionKeepsOnlyRegionInteriors) {
  // 6×4: a 3×3 block at x 0–2, y 1–3 (touching the left and bottom borders), one isolated
  // pixel at (5, 0). Only pixels whose in-image neighbours are all set survive: (0, 2) and
  // (1, 2) have every in-image neighbour inside the block; (0, 3), (1, 3) too (border).
  std::vector<uint8_t> m = {0, 0, 0, 0, 0, 1,  //
                            1, 1, 1, 0, 0, 0,  //
                            1, 1, 1, 0, 0, 0,  //
                            1, 1, 1, 0, 0, 0};
  erode_mask(m, 6, 4);
  EXPECT_EQ(m, (std::vector<uint8_t>{0, 0, 0, 0, 0, 0,  //
                                     0, 0, 0, 0, 0, 0,  //
                                     1, 1, 0, 0, 0, 0,  //
                                     1, 1, 0, 0, 0, 0}));
  std::vector<uint8_t> full(12, 1);
  erode_mask(full, 4, 3);
  EXPECT_EQ(full, std::vector<uint8_t>(12, 1));  // a fully unexplained frame stays whole
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { erode_mask(full, 5, 3); }), "does not match");
}

TEST(DistractorGrowth, ReseedPutsOneDistractorOnEachDrawnUnexplainedPixel) {
  Camera cam;
  cam.width = 8, cam.height = 6, cam.fx = cam.fy = 10, cam.cx = 4, cam.cy = 3;
  cam.t_cw = {0.5f, -0.25f, 1.0f};
  std::vector<uint8_t> mask(48, 0);
  mask[1 * 8 + 2] = mask[4 * 8 + 6] = mask[5 * 8 + 0] = 1;
  std::vector<float> target(48 * 3);
  for (size_t i = 0; i < target.size(); ++i) target[i] = float(i % 7) / 7.0f;
  DistractorSettings s;
  s.pixels_per_distractor = 4;  // a footprint of √4 = 2 px: σ of one pixel (checked below)
  const GaussianSet g = reseed_distractors(cam, mask, target, 10, s, 3);
  ASSERT_EQ(g.size(), 3u);  // only three pixels to draw from
  std::vector<int> hit;
  for (size_t i = 0; i < g.size(); ++i) {
    // Back into the camera: depth ρ and the pixel's centre.
    const auto [u, v, z] = project_mean(cam, g, i);
    EXPECT_NEAR(z, s.init_depth, 1e-6);
    EXPECT_NEAR(u - std::floor(u), 0.5, 1e-3);
    EXPECT_NEAR(v - std::floor(v), 0.5, 1e-3);
    const int p = int(std::floor(v)) * 8 + int(std::floor(u));
    EXPECT_TRUE(mask[p]) << p;
    hit.push_back(p);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(g.colors[3 * i + c], target[3 * p + c]);
    EXPECT_NEAR(1 / (1 + std::exp(-g.opacity_logits[i])), s.init_opacity, 1e-6);
    // σ = ρ·½·√A / f with A = 4: one pixel at the plane's depth.
    EXPECT_NEAR(std::exp(g.log_scales[3 * i]) * cam.fx / s.init_depth, 1.0, 1e-4);
  }
  // A = 16 spreads each seed over √16 = 4 px: σ of two pixels; without a cap (0), √4 again.
  s.pixels_per_distractor = 16;
  const GaussianSet wide = reseed_distractors(cam, mask, target, 10, s, 3);
  for (float ls : wide.log_scales) EXPECT_NEAR(std::exp(ls) * cam.fx / s.init_depth, 2.0, 1e-4);
  s.pixels_per_distractor = 0;
  const GaussianSet uncapped = reseed_distractors(cam, mask, target, 10, s, 3);
  for (float ls : uncapped.log_scales) EXPECT_NEAR(std::exp(ls) * cam.fx / s.init_depth, 1.0, 1e-4);
  s.pixels_per_distractor = 4;
  std::sort(hit.begin(), hit.end());
  EXPECT_EQ(hit, (std::vector<int>{10, 38, 40}));
  EXPECT_EQ(reseed_distractors(cam, mask, target, 2, s, 3).size(), 2u);
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { reseed_distractors(cam, mask, {}, 2, s, 3); }),
                  "does not match the camera");
}

TEST(ViewResidual, CountsAndPenalizesOnlyWhatTheStaticLayerExplains) {
  // Three pixels, black background, τ = 0.1 (mean |error| over RGB).
  // 0: static 0.5 grey opaque, target 0.52 → explained by static; composite also explains it.
  // 1: static 0.5, target 0.9 → unexplained by static; the distractor makes the composite right.
  // 2: static 0.2, target 0.8 → unexplained by both.
  const std::vector<float> sc = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.2f, 0.2f, 0.2f}, sa = {1, 1, 1};
  const std::vector<float> dc = {0, 0, 0, 0.9f, 0.9f, 0.9f, 0, 0, 0}, da = {0.25f, 1, 0};
  const std::vector<float> target = {0.52f, 0.52f, 0.52f, 0.9f, 0.9f, 0.9f, 0.8f, 0.8f, 0.8f};
  std::vector<float> composite(9);
  composite_layers({sc, sa}, {dc, da}, std::array<float, 3>{0, 0, 0}, composite);
  std::vector<float> d_alpha = {1, 1, 1};
  std::vector<uint8_t> mask;
  const ViewResidual r =
      measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, 3, ResidualPenalties{0.1f, 0.3f, 0.0f}, d_alpha, &mask);
  EXPECT_EQ(r.pixels, 3);
  EXPECT_EQ(r.static_unexplained, 2);
  // Pixel 0's composite is 0.75·0.5 = 0.375 (the distractor's black at α ¼): off by 0.145 → unexplained too.
  EXPECT_EQ(r.composite_unexplained, 2);
  EXPECT_EQ(mask, (std::vector<uint8_t>{0, 0, 1}));  // uncovered: neither layer explains it
  EXPECT_NEAR(r.penalty, 0.3 * 0.25 / 3, 1e-7);
  EXPECT_NEAR(d_alpha[0], 1 + 0.3f / 3, 1e-7);  // added only where static explains the pixel
  EXPECT_EQ(d_alpha[1], 1.0f);
  EXPECT_EQ(d_alpha[2], 1.0f);
}

// The owned-pixel pull: inside an area the static layer misses and the composite explains,
// the distractor layer is the explanation, and A_d is pulled up; nowhere else.
TEST(ViewResidual, PullsTheDistractorAlphaUpOnlyInsideAreasItAloneExplains) {
  // A 5×4 image, black background, τ = 0.1. The static layer is 0.5 grey and opaque
  // everywhere; the target is 0.5 except a 3×3 block (x 1–3, y 0–2) at 0.72, which the
  // static layer misses by 0.22. The distractor covers the block at α 0.6 with premultiplied
  // 0.5: 0.5 + 0.4·0.5 = 0.7, within τ. A block pixel is owned when its 8 neighbours inside
  // the image are in the block too: (2, 0) (its row above is outside) and (2, 1), pixels 2
  // and 7. The rest of the block touches pixels the static layer explains (its edge: fine
  // detail looks like that); the 11 outer pixels get the explained-pixel penalty instead.
  const int w = 5, h = 4, n = w * h;
  std::vector<float> sc(3 * n, 0.5f), sa(n, 1.0f), dc(3 * n, 0.0f), da(n, 0.0f), target(3 * n, 0.5f);
  for (int y = 0; y < 3; ++y)
    for (int x = 1; x < 4; ++x) {
      const int p = y * w + x;
      da[p] = 0.6f;
      for (int c = 0; c < 3; ++c) dc[3 * p + c] = 0.5f, target[3 * p + c] = 0.72f;
    }
  std::vector<float> composite(3 * n);
  composite_layers({sc, sa}, {dc, da}, std::array<float, 3>{0, 0, 0}, composite);
  ASSERT_NEAR(composite[3 * 7], 0.7f, 1e-6);
  std::vector<float> d_alpha(n, 0.0f);
  const ViewResidual r = measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, w,
                                               ResidualPenalties{0.1f, 0.3f, 0.2f}, d_alpha);
  EXPECT_EQ(r.static_unexplained, 9);
  EXPECT_EQ(r.composite_unexplained, 0);
  EXPECT_NEAR(r.penalty, 0.2 * 2 * (1 - 0.6) / n, 1e-7);  // A_d = 0 where the static layer explains
  for (int p = 0; p < n; ++p) {
    const bool in_block = p % w >= 1 && p % w <= 3 && p / w <= 2;
    const float expected = p == 2 || p == 7 ? -0.2f / n : in_block ? 0.0f : 0.3f / n;
    EXPECT_NEAR(d_alpha[p], expected, 1e-8) << "pixel " << p;
  }
  // The same residual on a 15×4 image would have other neighbours: the width is an input.
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] {
                    measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, 3,
                                          ResidualPenalties{0.1f, 0.3f, 0.2f}, d_alpha);
                  }),
                  "width");
}

// What the growth rules count (distractors.count_connected_misses): the static misses that
// survive a 3×3 opening. A 10×7 image, static 0.5 grey, opaque; the target is 0.9 (missed by
// 0.4) on a 4×3 block (x 1–4, y 1–3), a one-pixel line (y 5, x 1–6) and one pixel (8, 1).
// The block's interior is (2, 2) and (3, 2), whose 3×3 neighbourhoods cover the whole block:
// 12 pixels in areas. The line has no interior (rows 4 and 6 are explained), nor the lone pixel.
TEST(ViewResidual, CountsStaticMissesInsideConnectedAreasOnly) {
  const int w = 10, h = 7, n = w * h;
  std::vector<float> sc(3 * n, 0.5f), sa(n, 1.0f), target(3 * n, 0.5f);
  const auto miss = [&](int x, int y) {
    for (int c = 0; c < 3; ++c) target[3 * (y * w + x) + c] = 0.9f;
  };
  for (int y = 1; y <= 3; ++y)
    for (int x = 1; x <= 4; ++x) miss(x, y);
  for (int x = 1; x <= 6; ++x) miss(x, 5);
  miss(8, 1);
  std::vector<float> composite(3 * n);
  composite_layers({sc, sa}, {}, std::array<float, 3>{0, 0, 0}, composite);
  const ViewResidual r = measure_view_residual({sc, sa}, {}, composite, target, std::array<float, 3>{0, 0, 0}, w,
                                               ResidualPenalties{0.1f, 0.0f, 0.0f, true}, {});
  EXPECT_EQ(r.static_unexplained, 12 + 6 + 1);
  EXPECT_EQ(r.static_unexplained_in_areas, 12);
  EXPECT_NEAR(r.static_area_fraction(), 12.0 / n, 1e-12);
  // Not asked for (the default), the opening is skipped.
  EXPECT_EQ(measure_view_residual({sc, sa}, {}, composite, target, std::array<float, 3>{0, 0, 0}, w,
                                  ResidualPenalties{0.1f, 0.0f, 0.0f}, {})
                .static_unexplained_in_areas,
            0);
  // An ignored pixel is no miss (as for the owned-pixel pull): ignoring (2, 2) takes the
  // interior from both candidates, (2, 2) itself and its neighbour (3, 2), so no miss counts.
  std::vector<float> keep(n, 1.0f);
  keep[2 * w + 2] = 0;
  const ViewResidual k = measure_view_residual({sc, sa}, {}, composite, target, std::array<float, 3>{0, 0, 0}, w,
                                               ResidualPenalties{0.1f, 0.0f, 0.0f, true}, {}, nullptr, keep);
  EXPECT_EQ(k.static_unexplained, 18);
  EXPECT_EQ(k.static_unexplained_in_areas, 0);
}

// The same three pixels with pixel 2 (unexplained by both) ignored by the user's mask: it is in
// no count and never uncovered; the penalty averages over the two kept pixels.
TEST(ViewResidual, IgnoredPixelsAreInNoCountAndNeverUncovered) {
  const std::vector<float> sc = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.2f, 0.2f, 0.2f}, sa = {1, 1, 1};
  const std::vector<float> dc = {0, 0, 0, 0.9f, 0.9f, 0.9f, 0, 0, 0}, da = {0.25f, 1, 0};
  const std::vector<float> target = {0.52f, 0.52f, 0.52f, 0.9f, 0.9f, 0.9f, 0.8f, 0.8f, 0.8f};
  std::vector<float> composite(9);
  composite_layers({sc, sa}, {dc, da}, std::array<float, 3>{0, 0, 0}, composite);
  std::vector<float> d_alpha = {1, 1, 1};
  std::vector<uint8_t> mask;
  const std::vector<float> keep = {1, 1, 0};
  const ViewResidual r =
      measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, 3, ResidualPenalties{0.1f, 0.3f, 0.0f}, d_alpha, &mask, keep);
  EXPECT_EQ(r.pixels, 2);
  EXPECT_EQ(r.static_unexplained, 1);     // pixel 1 only
  EXPECT_EQ(r.composite_unexplained, 1);  // pixel 0 (see above)
  EXPECT_EQ(mask, (std::vector<uint8_t>{0, 0, 0}));
  EXPECT_NEAR(r.penalty, 0.3 * 0.25 / 2, 1e-7);
  EXPECT_NEAR(d_alpha[0], 1 + 0.3f / 2, 1e-7);
  EXPECT_EQ(d_alpha[2], 1.0f);
}

TEST(TrainerRules, StatisticsRulesReachTheTrainer) {
  // Without resolution switches, normalizing each step's gradient by its own image size or
  // the sum by the refinement's is the same number: the same Gaussians are densified, in
  // the static set and in every view's buffer.
  const TrainingData data = test::synthetic_training_data(8, 64, 48, 5);
  std::vector<std::pair<size_t, size_t>> counts;
  for (const bool per_step : {false, true}) {
    TrainConfig c;
    c.iterations = 151;
    c.sh_degree = 1;
    c.num_downscales = 0;
    c.densify.warmup = 100;
    c.densify.refine_every = 50;
    c.densify.stats.normalize_each_step = per_step;
    c.distractors.initial_count = 100;
    c.distractors.reference_pixels = 0;
    c.threads = 1;
    Trainer t(data, c);
    const size_t initial = t.gaussians().size();
    RefineReport distractor_refine;
    for (int i = 0; i < 151; ++i) {
      const StepStats s = t.step();
      distractor_refine += s.distractor_refine;
    }
    EXPECT_GT(t.gaussians().size(), initial);  // the refinement at step 150 densified
    EXPECT_GT(distractor_refine.high_gradient, 0);
    counts.push_back({t.gaussians().size(), t.distractor_count()});
  }
  EXPECT_EQ(counts[0], counts[1]);
}

// 8 synthetic views (64×48); training view 0 gets a white 24×24 square at x 20–43,
// y 12–35 that the other views do not show.
TrainingData views_with_a_one_view_square() {
  TrainingData data = test::synthetic_training_data(8, 64, 48, 5);
  ByteImage& img = data.train[0].image;
  for (int y = 12; y < 36; ++y)
    for (int x = 20; x < 44; ++x)
      for (int c = 0; c < 3; ++c) img.pixels[(size_t(y) * 64 + x) * 3 + c] = 255;
  return data;
}

// Short runs for the seeding tests: no resolution schedule unless asked, refinements every
// 50 steps from step 250, one epoch per distractor refinement (8 steps), 100 distractors per view.
TrainConfig seeding_test_config(int num_downscales = 0) {
  TrainConfig c;
  c.iterations = 400;
  c.sh_degree = 1;
  c.num_downscales = num_downscales;
  c.resolution_schedule = 250;
  c.random_background = false;
  c.densify.warmup = 200;
  c.densify.refine_every = 50;
  c.distractors.initial_count = 100;
  c.distractors.reference_pixels = 0;
  c.distractors.refine_every_epochs = 1;
  c.distractors.seed_after = 0;  // these tests seed within 400 steps
  c.threads = 1;
  return c;
}

TEST(TrainerRules, TheAlphaSumLimitStopsCopiesAndIsMeasuredOnlyWhenOn) {
  // The same run twice: without the limit the distractor refinements copy high-gradient
  // distractors; with a limit no buffer can be under (10⁻⁶ of a pixel's alpha per unexplained
  // pixel), every view's budget is 0 and nothing is copied, and each refinement records the
  // buffer's summed alpha it was judged on.
  const TrainingData data = views_with_a_one_view_square();
  int64_t copied[2] = {0, 0};
  for (const bool limited : {false, true}) {
    TrainConfig c = seeding_test_config();
    c.distractors.reseed_starved_views = false;
    c.distractors.seed_uncovered = false;
    c.distractors.max_alpha_sum = limited ? 1e-6f : 0.0f;
    Trainer t(data, c);
    int refinements = 0;
    for (int i = 0; i < c.iterations; ++i) {
      const StepStats s = t.step();
      for (const ViewRefinement& r : s.distractor_refinements) {
        ++refinements;
        copied[limited] += r.report.split + r.report.duplicated;
        if (limited) {
          EXPECT_GT(r.alpha_sum, 0.0);
          EXPECT_EQ(r.budget, 0);
        } else {
          EXPECT_EQ(r.alpha_sum, 0.0);  // not measured when off
        }
      }
    }
    EXPECT_GT(refinements, 0);
  }
  EXPECT_GT(copied[0], 0);
  EXPECT_EQ(copied[1], 0);
}

TEST(TrainerRules, AnEmptiedBufferOverAnOccluderIsSeededThere) {
  // Training view 0 gets a white 24×24 square the other views do not show; its buffer is
  // emptied. At the next distractor refinement the view is starved (and uncovered), and its
  // next step seeds it on pixels drawn from the interiors of what neither layer explains:
  // the square's 22×22 interior and what survives erosion of the (still rough) scene's
  // residual. Either rule alone does it. Every seed sits on a pixel of the mask, and the
  // share on the square is its share of the mask, up to the draw's binomial noise.
  const TrainingData data = views_with_a_one_view_square();
  for (const bool starved_rule : {true, false}) {
    TrainConfig c = seeding_test_config();
    c.distractors.reseed_starved_views = starved_rule;
    c.distractors.seed_uncovered = !starved_rule;
    Trainer t(data, c);
    int64_t reseeded = 0;
    for (int i = 0; i < 400 && reseeded == 0; ++i) {
      if (i < 250) t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
      reseeded = t.step().reseeded;
    }
    ASSERT_GT(reseeded, 0) << "starved rule " << starved_rule;
    const GaussianSet& seeds = t.distractors()[0].params;
    ASSERT_EQ(int64_t(seeds.size()), reseeded);
    const std::vector<uint8_t>& mask = t.uncovered_mask();
    ASSERT_EQ(mask.size(), size_t(64 * 48));
    int64_t mask_pixels = 0, mask_in_square = 0;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        mask_pixels += mask[size_t(y) * 64 + x];
        mask_in_square += mask[size_t(y) * 64 + x] && x >= 20 && x < 44 && y >= 12 && y < 36;
      }
    EXPECT_GE(mask_in_square, 22 * 22 * 9 / 10);  // the static layer cannot fit a one-view square
    const Camera& cam = data.train[0].camera;
    int inside = 0;
    for (size_t i = 0; i < seeds.size(); ++i) {
      const auto [u, v, z] = project_mean(cam, seeds, i);
      const int px = int(std::floor(u)), py = int(std::floor(v));
      ASSERT_TRUE(px >= 0 && py >= 0 && px < 64 && py < 48 && mask[size_t(py) * 64 + px]) << u << ", " << v;
      inside += px >= 20 && px < 44 && py >= 12 && py < 36;
    }
    const double p = double(mask_in_square) / double(mask_pixels), n = double(seeds.size());
    EXPECT_NEAR(double(inside) / n, p, 3 * std::sqrt(p * (1 - p) / n) + 1e-9) << inside << " of " << seeds.size();
    EXPECT_GT(p, 2 * 576.0 / (64 * 48));  // and the square is far more than its share of the frame
  }
}

// Eight 64×48 views; view 0 alone shows a 24×24 square (x 20–43, y 12–35) 50/255 brighter.
TrainingData views_with_a_brighter_square_in_view_0() {
  TrainingData data = test::synthetic_training_data(8, 64, 48, 5);
  ByteImage& img = data.train[0].image;
  for (int y = 12; y < 36; ++y)
    for (int x = 20; x < 44; ++x)
      for (int c = 0; c < 3; ++c) {
        uint8_t& v = img.pixels[(size_t(y) * 64 + x) * 3 + c];
        v = uint8_t(std::min(255, v + 50));
      }
  return data;
}

// The owned-pixel pull in a trainer: view 0 alone shows a 24×24 square 50/255 brighter than
// the scene, an area the static layer misses and the distractors come to explain. A partly
// transparent distractor fits it (a white one would need α = 1); with the pull on, the
// distractors over it end more opaque. Before `owned_after` the pull is off: training is bit
// for bit the run without it.
TEST(TrainerRules, TheOwnedPixelPullMakesAOneViewSquaresDistractorsOpaqueFromItsStepOn) {
  const TrainingData data = views_with_a_brighter_square_in_view_0();
  auto run = [&](float lambda_owned, int owned_after) {
    TrainConfig c = seeding_test_config();
    c.distractors.lambda_owned = lambda_owned;
    c.distractors.owned_after = owned_after;
    c.distractors.lambda_occluder_colour = 0.0f;  // starts at owned_after too: the pull alone here
    Trainer t(data, c);
    for (int i = 0; i < 400; ++i) t.step();
    return t;
  };
  const Trainer off = run(0.0f, 0), on = run(1.0f, 0), later = run(1.0f, 400);
  auto square_alpha = [](const Trainer& t) {
    const ViewLayers layers = t.render_layers(0, {0, 0, 0});
    double sum = 0;
    for (int y = 14; y < 34; ++y)
      for (int x = 22; x < 42; ++x) sum += layers.distractor_alpha.pixels[size_t(y) * 64 + x];
    return sum / (20 * 20);
  };
  const double a_off = square_alpha(off), a_on = square_alpha(on);
  EXPECT_GT(a_on, a_off + 0.2) << a_on << " against " << a_off;
  EXPECT_EQ(square_alpha(later), a_off);
  EXPECT_EQ(later.distractors()[0].params.means, off.distractors()[0].params.means);
  EXPECT_EQ(later.gaussians().params.means, off.gaussians().params.means);
}

// The occluder-colour prior in a trainer, on the owned pull's scene (a one-view square 50/255
// brighter than the scene): with the prior on and the owned pull off, the distractors over the
// square end more opaque, and their own colour (C_d / A_d) nearer the photo's, than without it.
// Before owned_after the prior is off: training is bit for bit the run without it.
TEST(TrainerRules, TheOccluderColourPriorMakesAOneViewSquaresDistractorsOpaqueAndPhotoColoured) {
  const TrainingData data = views_with_a_brighter_square_in_view_0();
  const ByteImage& img = data.train[0].image;
  auto run = [&](float lambda, int after) {
    TrainConfig c = seeding_test_config();
    c.distractors.lambda_owned = 0.0f;
    c.distractors.lambda_occluder_colour = lambda;
    c.distractors.owned_after = after;
    // The margin below holds at 4 px per distractor, set here whatever the default: at 8 the
    // 24×24 square holds half as many, and 400 steps leave the prior too little alpha to tell.
    c.distractors.pixels_per_distractor = 4;
    Trainer t(data, c);
    for (int i = 0; i < 400; ++i) t.step();
    return t;
  };
  const Trainer off = run(0.0f, 0), on = run(1.0f, 0), later = run(1.0f, 400);
  struct Square { double alpha, colour_error; };
  auto square = [&](const Trainer& t) {
    const ViewLayers layers = t.render_layers(0, {0, 0, 0});  // distractor over black: C_d
    Square s{0, 0};
    int n = 0;
    for (int y = 14; y < 34; ++y)
      for (int x = 22; x < 42; ++x) {
        const size_t p = size_t(y) * 64 + x;
        const double a = layers.distractor_alpha.pixels[p];
        s.alpha += a;
        if (a < 0.05) continue;
        for (int c = 0; c < 3; ++c)
          s.colour_error += std::abs(layers.distractor.pixels[3 * p + c] / a - img.pixels[3 * p + c] / 255.0);
        n += 3;
      }
    s.alpha /= 20 * 20;
    s.colour_error /= std::max(n, 1);
    return s;
  };
  const Square a_off = square(off), a_on = square(on);
  // Training is deterministic: the margin asks for an effect of a size that matters, not noise.
  EXPECT_GT(a_on.alpha, a_off.alpha + 0.05) << a_on.alpha << " against " << a_off.alpha;
  EXPECT_LT(a_on.colour_error, a_off.colour_error) << a_on.colour_error << " against " << a_off.colour_error;
  EXPECT_EQ(later.distractors()[0].params.means, off.distractors()[0].params.means);
  EXPECT_EQ(later.distractors()[0].params.colors, off.distractors()[0].params.colors);
  EXPECT_EQ(later.gaussians().params.means, off.gaussians().params.means);
}

TEST(TrainerRules, SeedingWaitsOnePeriodAfterAResolutionSwitch) {
  // Two downscales every 3,000 steps, a 430-step refinement period (10 epochs of 43 views).
  TrainConfig c;
  c.num_downscales = 2;
  c.resolution_schedule = 3000;
  EXPECT_TRUE(resolution_settled(c, 100, 430));    // before one period: compared with step 0
  EXPECT_TRUE(resolution_settled(c, 2999, 430));
  EXPECT_FALSE(resolution_settled(c, 3000, 430));  // factor 2 now, 4 at step 2,570
  EXPECT_FALSE(resolution_settled(c, 3429, 430));
  EXPECT_TRUE(resolution_settled(c, 3430, 430));
  EXPECT_FALSE(resolution_settled(c, 6100, 430));
  EXPECT_TRUE(resolution_settled(c, 9000, 430));   // full resolution from 6,000 on

  // In a trainer: view 0 over a one-view white square, its buffer emptied before every step
  // up to 249. 8 views and one epoch per distractor refinement: a period of 8 steps;
  // refinements every 50 steps from 250. Without downscales the refinement at 250 marks the
  // view and its next visit (≤ 8 steps on) seeds it; with the resolution switching at 250
  // that refinement is too early, and seeding waits for the one at 300.
  const TrainingData data = views_with_a_one_view_square();
  for (const int downscales : {0, 1}) {
    Trainer t(data, seeding_test_config(downscales));
    int64_t seeded_at = -1;
    for (int i = 0; i < 400 && seeded_at < 0; ++i) {
      if (i < 250) t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
      if (t.step().reseeded > 0) seeded_at = i;
    }
    if (downscales == 0) {
      EXPECT_GT(seeded_at, 250);
      EXPECT_LE(seeded_at, 258);
    } else {
      EXPECT_GT(seeded_at, 300);
      EXPECT_LE(seeded_at, 308);
    }
  }
}

TEST(TrainerRules, SeedingWaitsForSeedAfterAndOnePeriodAfterAnOpacityReset) {
  // --preset fast's schedule at one resolution: refinements every 100 steps after a 200-step
  // warm-up, an opacity reset at the first refinement of every 1,000 steps (1,100 and
  // 2,100; none from stop_split_at 2,500 on), seeding from step 1,000, a 105-step period.
  TrainConfig c;
  c.num_downscales = 0;
  c.densify.warmup = 200;
  c.densify.refine_every = 100;
  c.densify.reset_alpha_every = 10;
  c.densify.stop_split_at = 2500;
  std::vector<int64_t> resets;
  for (int64_t s = 0; s < 5000; ++s)
    if (opacity_reset_due(c.densify, s)) resets.push_back(s);
  EXPECT_EQ(resets, (std::vector<int64_t>{1100, 2100}));
  c.densify.warmup = 1100;  // a reset on the warm-up's last step does not happen
  EXPECT_FALSE(opacity_reset_due(c.densify, 1100));
  c.densify.warmup = 200;

  c.distractors.seed_after = 1000;
  c.distractors.seed_waits_after_reset = true;
  EXPECT_FALSE(seeding_allowed(c, 999, 105));
  EXPECT_TRUE(seeding_allowed(c, 1000, 105));
  EXPECT_TRUE(seeding_allowed(c, 1099, 105));
  EXPECT_FALSE(seeding_allowed(c, 1100, 105));
  EXPECT_FALSE(seeding_allowed(c, 1204, 105));  // 1,100 is within the last 105 steps
  EXPECT_TRUE(seeding_allowed(c, 1205, 105));
  EXPECT_FALSE(seeding_allowed(c, 2150, 105));
  EXPECT_TRUE(seeding_allowed(c, 3100, 105));   // no reset from stop_split_at on
  c.distractors.seed_waits_after_reset = false;
  EXPECT_TRUE(seeding_allowed(c, 1100, 105));
  c.distractors.seed_after = 0;
  EXPECT_TRUE(seeding_allowed(c, 300, 105));

  // In a trainer (as SeedingWaitsOnePeriodAfterAResolutionSwitch, one resolution): the
  // refinement at 250 would seed the emptied view within 8 steps. With seeding from step 300,
  // or with an opacity reset at 250 (every 4 refinements of 50 steps: 250 % 200 = 50), that
  // refinement is too early and the one at 300 seeds it.
  const TrainingData data = views_with_a_one_view_square();
  for (const bool reset : {false, true}) {
    TrainConfig tc = seeding_test_config(0);
    if (reset) {
      tc.densify.reset_alpha_every = 4;
      tc.distractors.seed_waits_after_reset = true;
    } else {
      tc.distractors.seed_after = 300;
    }
    Trainer t(data, tc);
    int64_t seeded_at = -1;
    for (int i = 0; i < 400 && seeded_at < 0; ++i) {
      if (i < 250) t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
      if (t.step().reseeded > 0) seeded_at = i;
    }
    EXPECT_GT(seeded_at, 300) << "reset " << reset;
    EXPECT_LE(seeded_at, 308) << "reset " << reset;
  }
}

TEST(Presets, PaperIsTheAuthorsBehaviourAndDefaultIsTrainConfig) {
  const TrainConfig paper = preset_config("paper");
  EXPECT_TRUE(paper.densify.stats.visible_count_from_one);
  EXPECT_TRUE(paper.densify.stats.radius_from_eigenvalue);
  EXPECT_FALSE(paper.densify.stats.hide_behind_distractors);
  EXPECT_FALSE(paper.densify.stats.gradient_per_seen_pixel);
  EXPECT_FALSE(paper.densify.stats.normalize_each_step);
  EXPECT_FALSE(paper.densify.split_screen_needs_grad);
  EXPECT_FALSE(paper.densify.inherit_moments);
  EXPECT_EQ(paper.distractors.reference_pixels, 0);
  EXPECT_EQ(paper.distractors.initial_count, 1000);
  EXPECT_EQ(paper.distractors.pixels_per_distractor, 0);
  EXPECT_EQ(paper.distractors.lambda_explained, 0.0f);
  EXPECT_EQ(paper.distractors.lambda_mask_tv, 0.0f);
  EXPECT_EQ(paper.distractors.lambda_occluder_colour, 0.0f);
  EXPECT_EQ(paper.distractors.lambda_owned, 0.0f);
  EXPECT_EQ(paper.distractors.refine_every_epochs, 10);
  EXPECT_FALSE(paper.distractors.reseed_starved_views);
  EXPECT_FALSE(paper.distractors.seed_uncovered);
  EXPECT_EQ(paper.distractors.grow_after, 0);
  EXPECT_EQ(paper.distractors.seed_after, 0);
  EXPECT_EQ(paper.distractors.min_blend_weight, 0.0f);  // no idle cull
  EXPECT_EQ(paper.distractors.max_alpha_sum, 0.0f);     // no opacity limit on copies
  EXPECT_EQ(paper.transient_points.action, TransientPointAction::keep);
  EXPECT_EQ(paper.appearance.hidden_width, 128);  // the paper's appendix
  EXPECT_EQ(paper.appearance.lr_image, 1e-3f);     // the appendix's rate
  EXPECT_EQ(paper.background.lambda_opaque, 0.0f);  // the authors' L_bg alone
  EXPECT_EQ(paper.background.lambda_alpha, 0.15f);
  EXPECT_EQ(paper.background.hidden_width, 128);
  EXPECT_EQ(paper.background.lr_image, 1e-3f);
  // The defaults docs/METHOD.md §7 documents (their measurements: docs/BENCHMARKS.md).
  const TrainConfig def = preset_config("default");
  EXPECT_TRUE(def.densify.stats.normalize_each_step);
  EXPECT_FALSE(def.densify.stats.visible_count_from_one);
  EXPECT_TRUE(def.densify.split_screen_needs_grad);
  EXPECT_EQ(def.distractors.pixels_per_distractor, 6);
  EXPECT_FALSE(def.distractors.count_connected_misses);  // measured, not kept
  EXPECT_FALSE(def.densify.stats.hide_behind_distractors);  // measured, not kept
  EXPECT_TRUE(def.densify.stats.gradient_per_seen_pixel);
  EXPECT_EQ(def.appearance.lr_image, def.appearance.test_lr);  // the embeddings' rate, METHOD §10
  EXPECT_EQ(def.background.lr_image, def.appearance.lr_image);  // an own copy trains as the shared one
  EXPECT_EQ(def.distractors.lambda_explained, 0.05f);
  EXPECT_EQ(def.distractors.lambda_mask_tv, 0.1f);
  EXPECT_EQ(def.distractors.lambda_occluder_colour, 0.4f);  // half the L1 weight 0.8
  EXPECT_TRUE(def.distractors.reseed_starved_views);
  EXPECT_TRUE(def.distractors.seed_uncovered);
  EXPECT_EQ(def.distractors.grow_after, 0);
  EXPECT_EQ(def.distractors.lambda_owned, 0.2f);
  EXPECT_EQ(def.distractors.owned_after, def.resolution_schedule);  // the first resolution switch
  EXPECT_EQ(def.distractors.seed_after, def.resolution_schedule);   // the first resolution switch
  EXPECT_TRUE(def.distractors.seed_waits_after_reset);
  EXPECT_EQ(def.distractors.min_blend_weight, 0.0f);  // the idle cull, measured, not kept
  EXPECT_EQ(def.distractors.max_alpha_sum, 2.3f);     // ≈ ln 10
  EXPECT_EQ(def.distractors.refine_every_epochs, 3);
  EXPECT_EQ(def.transient_points.action, TransientPointAction::drop);
  EXPECT_EQ(def.transient_points.min_track_images, 3);
  EXPECT_EQ(def.transient_points.color_tolerance, 0.25f);
  EXPECT_EQ(def.appearance.hidden_width, 32);  // not the paper's 128, METHOD §10
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] { preset_config("fastest"); }),
                  "unknown preset 'fastest' (known: fast, default, paper)");
}

// The fast preset is the default's schedule fitted into its own length: every phase the
// default goes through must also happen, in order, before the fast run ends.
TEST(Presets, FastGoesThroughEveryPhaseOfTheScheduleWithinItsSteps) {
  const TrainConfig fast = preset_config("fast");
  EXPECT_NO_THROW(validate_config(fast));
  ASSERT_EQ(fast.iterations, 3000);
  // A third of the run at 1/4, 1/2 and full resolution.
  EXPECT_EQ(fast.downscale_at(0), 4);
  EXPECT_EQ(fast.downscale_at(999), 4);
  EXPECT_EQ(fast.downscale_at(1000), 2);
  EXPECT_EQ(fast.downscale_at(2000), 1);
  EXPECT_EQ(fast.full_resolution_from(), 2000);
  // Full SH degree before full resolution.
  EXPECT_EQ(fast.sh_degree_at(fast.full_resolution_from() - 1), fast.sh_degree);
  // Densification starts, stops with steps left to settle, and resets opacity inside the run.
  EXPECT_LT(fast.densify.warmup, fast.full_resolution_from());
  EXPECT_LT(fast.densify.stop_split_at, fast.iterations);
  const int64_t reset_every = int64_t(fast.densify.reset_alpha_every) * fast.densify.refine_every;
  EXPECT_LT(reset_every, fast.densify.stop_split_at);
  // Positions decay over this run's length.
  EXPECT_EQ(fast.means_lr_decay_steps, fast.iterations);
  // The owned-pixel pull starts at the first resolution switch, as in the default.
  EXPECT_EQ(fast.distractors.owned_after, fast.resolution_schedule);
  // Every view's distractor buffer is refined at least 10 times while densifying with ~50 views.
  int refinements = 0;
  for (int64_t step = 0; step < fast.densify.stop_split_at; ++step)
    refinements += distractor_refine_due(step, 50, fast.densify, fast.distractors) ? 1 : 0;
  EXPECT_GE(refinements, 10);
  // Everything else is the default's.
  TrainConfig same = fast;
  const TrainConfig def;
  same.iterations = def.iterations;
  same.resolution_schedule = def.resolution_schedule;
  same.sh_degree_interval = def.sh_degree_interval;
  same.background.sh_degree_interval = def.background.sh_degree_interval;
  same.means_lr_decay_steps = def.means_lr_decay_steps;
  same.densify.warmup = def.densify.warmup;
  same.densify.stop_split_at = def.densify.stop_split_at;
  same.densify.stop_screen_size_at = def.densify.stop_screen_size_at;
  same.densify.reset_alpha_every = def.densify.reset_alpha_every;
  same.distractors.owned_after = def.distractors.owned_after;
  // Seeding from the warm-up on.
  EXPECT_EQ(fast.distractors.seed_after, 0);
  EXPECT_FALSE(fast.distractors.seed_waits_after_reset);
  same.distractors.seed_after = def.distractors.seed_after;
  same.distractors.seed_waits_after_reset = def.distractors.seed_waits_after_reset;
  EXPECT_EQ(config_to_json(same).dump(), config_to_json(def).dump());
}

TEST(TrainerRules, HideUnseenCentersHidesCentresOnIgnoredPixelsAndBehindADistractorMask) {
  // A 4×2 image; five visible Gaussians but one. Centres: pixel 0 (ignored), pixel 1 (A_d
  // 0.6), pixel 2 (A_d exactly the threshold 0.5: still seen), pixel 7 (A_d 0.9, already not
  // visible) and one left of the image (no pixel to judge: stays visible).
  RasterOutput fw;
  fw.width = 4, fw.height = 2;
  fw.means2d = {0.5f, 0.5f, 1.5f, 0.5f, 2.5f, 0.5f, 3.5f, 1.5f, -1.0f, 0.5f};
  fw.visible = {1, 1, 1, 0, 1};
  const std::vector<float> keep = {0, 1, 1, 1, 1, 1, 1, 1};
  const std::vector<float> alpha = {0, 0.6f, 0.5f, 0, 0, 0, 0, 0.9f};
  RasterOutput both = fw;
  hide_unseen_centers(both, keep, alpha);
  EXPECT_EQ(both.visible, (std::vector<uint8_t>{0, 0, 1, 0, 1}));
  RasterOutput keep_only = fw;
  hide_unseen_centers(keep_only, keep, {});
  EXPECT_EQ(keep_only.visible, (std::vector<uint8_t>{0, 1, 1, 0, 1}));
  RasterOutput alpha_only = fw;
  hide_unseen_centers(alpha_only, {}, alpha);
  EXPECT_EQ(alpha_only.visible, (std::vector<uint8_t>{1, 0, 1, 0, 1}));
}

TEST(TrainerRules, SeenPixelGradientScaleIsKeptPixelsOverSeenPixels) {
  // Four pixels, the last one ignored: kept 3, seen 1 + 0.5 + 0 = 1.5, so 2.
  const std::vector<float> keep = {1, 1, 1, 0}, alpha = {0, 0.5f, 1, 0.3f};
  EXPECT_NEAR(seen_pixel_gradient_scale(keep, alpha), 2.0f, 1e-6f);
  // Every pixel kept: 4 / (1 + 0.5 + 0 + 0.7).
  EXPECT_NEAR(seen_pixel_gradient_scale({}, alpha), 4.0f / 2.2f, 1e-6f);
  // No distractor layer, a transparent one, or one that hides every kept pixel: unchanged.
  EXPECT_EQ(seen_pixel_gradient_scale(keep, {}), 1.0f);
  EXPECT_EQ(seen_pixel_gradient_scale(keep, std::vector<float>(4, 0.0f)), 1.0f);
  const std::vector<float> first_two = {1, 1, 0, 0}, covering_them = {1, 1, 0.2f, 0.7f};
  EXPECT_EQ(seen_pixel_gradient_scale(first_two, covering_them), 1.0f);
}

// `steps` steps of seeding_test_config, changed by `change`, with no static refinement within
// the run: the densification statistics never feed back into what is trained.
Trainer train_without_static_refinement(const TrainingData& data, const std::function<void(TrainConfig&)>& change,
                                        int steps = 400) {
  TrainConfig c = seeding_test_config();
  c.densify.warmup = 10000;
  change(c);
  Trainer t(data, c);
  for (int i = 0; i < steps; ++i) t.step();
  return t;
}

TEST(TrainerRules, StaticGradientsJudgedPerSeenPixelOnlyWhereDistractorsAre) {
  // Both runs train the same Gaussians. Judged per seen pixel, a static Gaussian's gradient sum
  // can only grow (the scale is ≥ 1), and it grows for some: view 0's distractors cover part of
  // its frame.
  const TrainingData data = views_with_a_one_view_square();
  auto run = [&](bool per_seen_pixel) {
    return train_without_static_refinement(
        data, [&](TrainConfig& c) { c.densify.stats.gradient_per_seen_pixel = per_seen_pixel; });
  };
  const Trainer off = run(false), on = run(true);
  EXPECT_EQ(on.gaussians().params.means, off.gaussians().params.means);
  EXPECT_EQ(on.gaussians().visible_count, off.gaussians().visible_count);
  const std::vector<float>& sum_on = on.gaussians().absgrad_sum;
  const std::vector<float>& sum_off = off.gaussians().absgrad_sum;
  ASSERT_EQ(sum_on.size(), sum_off.size());
  int64_t larger = 0;
  for (size_t i = 0; i < sum_on.size(); ++i) {
    EXPECT_GE(sum_on[i], sum_off[i] * (1 - 1e-6f)) << "Gaussian " << i;
    larger += sum_on[i] > sum_off[i] * 1.001f ? 1 : 0;
  }
  EXPECT_GT(larger, 0);
  // Without distractors the rule changes nothing: a static-only run's statistics are the same.
  auto static_only = [&](bool per_seen_pixel) {
    const Trainer t = train_without_static_refinement(
        data,
        [&](TrainConfig& c) {
          c.distractors.enabled = false;
          c.densify.stats.gradient_per_seen_pixel = per_seen_pixel;
        },
        50);
    return t.gaussians().absgrad_sum;
  };
  EXPECT_EQ(static_only(true), static_only(false));
}

TEST(TrainerRules, StaticGaussiansBehindADistractorMaskAreNotCountedAsSeen) {
  // Both runs train the same Gaussians, and with the switch on a static Gaussian counts a step
  // only when its centre is not behind view 0's distractors over the square.
  const TrainingData data = views_with_a_one_view_square();
  auto run = [&](bool hide) {
    return train_without_static_refinement(data, [&](TrainConfig& c) { c.densify.stats.hide_behind_distractors = hide; });
  };
  const Trainer off = run(false), on = run(true);
  EXPECT_EQ(on.gaussians().params.means, off.gaussians().params.means);
  const std::vector<int32_t>& seen_on = on.gaussians().visible_count;
  const std::vector<int32_t>& seen_off = off.gaussians().visible_count;
  ASSERT_EQ(seen_on.size(), seen_off.size());
  int64_t hidden = 0;
  for (size_t i = 0; i < seen_on.size(); ++i) {
    EXPECT_LE(seen_on[i], seen_off[i]) << "Gaussian " << i;
    hidden += seen_off[i] - seen_on[i];
  }
  // View 0 is drawn 50 times in 400 steps; its square's distractors hide some static centres.
  EXPECT_GT(hidden, 0);
  const ViewLayers layers = on.render_layers(0, {0, 0, 0});
  EXPECT_GT(*std::max_element(layers.distractor_alpha.pixels.begin(), layers.distractor_alpha.pixels.end()),
            kDistractorMaskThreshold);
}

}  // namespace
}  // namespace desplat
