// The distractor growth rules of docs/METHOD.md §8, each on a hand-computed case: the cap,
// starved buffers and their re-seeding, the idle cull, the alpha-sum budget, and the per-step
// residual (explained-pixel penalty, owned-pixel pull, ignored pixels).
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

using test::project_mean;

float logit(float p) { return std::log(p / (1 - p)); }

TEST(DistractorGrowth, CapIsUnexplainedPixelsPerDistractor) {
  DistractorSettings s;
  s.pixels_per_distractor = 0;
  EXPECT_EQ(distractor_growth_budget(100, 0.1, 10000, s), kUnlimitedGrowth);  // off at 0 (paper)
  s.pixels_per_distractor = 16;
  EXPECT_EQ(distractor_cap(0.1, 10000, s), 62);  // 1,000 px / 16
  EXPECT_EQ(distractor_growth_budget(50, 0.1, 10000, s), 12);
  EXPECT_EQ(distractor_growth_budget(80, 0.1, 10000, s), 0);  // over the cap: no growth (no forced shrink)
  EXPECT_EQ(distractor_growth_budget(0, 0.0, 10000, s), 0);
  EXPECT_EQ(distractor_cap(2.0, 160, s), 10);  // fraction clamped to 1
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
  const GaussianSet g = round_distractors(
      {{0.0f, 0.0f, 1.0f, 0.1f, 0.5f}, {0.0f, 0.0f, 2.0f, 0.1f, 0.8f}, {0.0f, 0.0f, -1.0f, 0.1f, 0.9f}});
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
  EXPECT_EQ(alpha_sum_budget(100, 4500.0, 0.1, 10000, s), 0);            // at the limit
  EXPECT_EQ(alpha_sum_budget(100, 9000.0, 0.1, 10000, s), 0);            // over it: no growth, no forced shrink
  EXPECT_EQ(alpha_sum_budget(100, 10.0, 0.0, 10000, s), 0);              // nothing unexplained
  EXPECT_EQ(alpha_sum_budget(10, 10.0, 3.0, 100, s), 440);               // fraction clamped to 1: (450 − 10) / 1
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

// Three pixels, black background, τ = 0.1 (mean |error| over RGB):
// 0: static 0.5 grey opaque, target 0.52 → explained by static; composite also explains it.
// 1: static 0.5, target 0.9 → unexplained by static; the distractor makes the composite right.
// 2: static 0.2, target 0.8 → unexplained by both.
struct ThreePixels {
  std::vector<float> sc = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.2f, 0.2f, 0.2f}, sa = {1, 1, 1};
  std::vector<float> dc = {0, 0, 0, 0.9f, 0.9f, 0.9f, 0, 0, 0}, da = {0.25f, 1, 0};
  std::vector<float> target = {0.52f, 0.52f, 0.52f, 0.9f, 0.9f, 0.9f, 0.8f, 0.8f, 0.8f};
  std::vector<float> composite = std::vector<float>(9);
  ThreePixels() { composite_layers({sc, sa}, {dc, da}, std::array<float, 3>{0, 0, 0}, composite); }
};

TEST(ViewResidual, CountsAndPenalizesOnlyWhatTheStaticLayerExplains) {
  const ThreePixels pixels;
  const auto& [sc, sa, dc, da, target, composite] = pixels;
  std::vector<float> d_alpha = {1, 1, 1};
  std::vector<uint8_t> mask;
  const ViewResidual r = measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, 3,
                                               ResidualPenalties{0.1f, 0.3f, 0.0f}, d_alpha, &mask);
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

// The ThreePixels with pixel 2 (unexplained by both) ignored by the user's mask: it is in
// no count and never uncovered; the penalty averages over the two kept pixels.
TEST(ViewResidual, IgnoredPixelsAreInNoCountAndNeverUncovered) {
  const ThreePixels pixels;
  const auto& [sc, sa, dc, da, target, composite] = pixels;
  std::vector<float> d_alpha = {1, 1, 1};
  std::vector<uint8_t> mask;
  const std::vector<float> keep = {1, 1, 0};
  const ViewResidual r = measure_view_residual({sc, sa}, {dc, da}, composite, target, std::array<float, 3>{0, 0, 0}, 3,
                                               ResidualPenalties{0.1f, 0.3f, 0.0f}, d_alpha, &mask, keep);
  EXPECT_EQ(r.pixels, 2);
  EXPECT_EQ(r.static_unexplained, 1);     // pixel 1 only
  EXPECT_EQ(r.composite_unexplained, 1);  // pixel 0 (see above)
  EXPECT_EQ(mask, (std::vector<uint8_t>{0, 0, 0}));
  EXPECT_NEAR(r.penalty, 0.3 * 0.25 / 2, 1e-7);
  EXPECT_NEAR(d_alpha[0], 1 + 0.3f / 2, 1e-7);
  EXPECT_EQ(d_alpha[2], 1.0f);
}

}  // namespace
}  // namespace desplat
