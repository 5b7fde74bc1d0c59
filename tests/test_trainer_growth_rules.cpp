// The growth rules of docs/METHOD.md §7–8 as the Trainer applies them: statistics, the
// alpha-sum limit, seeding and its waits, the owned-pixel pull, the occluder colour prior, and
// which static Gaussians count as seen.
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
      if (i < 250)
        t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
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
    // The margin below holds for 4 px per distractor: with more pixels each, the 24×24 square
    // holds fewer distractors and 400 steps leave the prior too little alpha to tell apart.
    c.distractors.pixels_per_distractor = 4;
    Trainer t(data, c);
    for (int i = 0; i < 400; ++i) t.step();
    return t;
  };
  const Trainer off = run(0.0f, 0), on = run(1.0f, 0), later = run(1.0f, 400);
  struct Square {
    double alpha, colour_error;
  };
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
  EXPECT_TRUE(resolution_settled(c, 100, 430));  // before one period: compared with step 0
  EXPECT_TRUE(resolution_settled(c, 2999, 430));
  EXPECT_FALSE(resolution_settled(c, 3000, 430));  // factor 2 now, 4 at step 2,570
  EXPECT_FALSE(resolution_settled(c, 3429, 430));
  EXPECT_TRUE(resolution_settled(c, 3430, 430));
  EXPECT_FALSE(resolution_settled(c, 6100, 430));
  EXPECT_TRUE(resolution_settled(c, 9000, 430));  // full resolution from 6,000 on

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
      if (i < 250)
        t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
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
  EXPECT_TRUE(seeding_allowed(c, 3100, 105));  // no reset from stop_split_at on
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
      if (i < 250)
        t.mutable_distractors()[0] = TrainableGaussians(GaussianSet{{}, {}, {}, {}, {}, ColorMode::RGB, 0, {}, 0});
      if (t.step().reseeded > 0) seeded_at = i;
    }
    EXPECT_GT(seeded_at, 300) << "reset " << reset;
    EXPECT_LE(seeded_at, 308) << "reset " << reset;
  }
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
    return train_without_static_refinement(data,
                                           [&](TrainConfig& c) { c.densify.stats.hide_behind_distractors = hide; });
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
