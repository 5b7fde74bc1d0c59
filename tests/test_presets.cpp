// The named presets (train/presets.hpp): paper is the authors' behaviour, default is
// TrainConfig, and fast goes through every phase of the schedule within its steps.
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
  EXPECT_EQ(paper.appearance.hidden_width, 128);    // the paper's appendix
  EXPECT_EQ(paper.appearance.lr_image, 1e-3f);      // the appendix's rate
  EXPECT_EQ(paper.background.lambda_opaque, 0.0f);  // the authors' L_bg alone
  EXPECT_EQ(paper.background.lambda_alpha, 0.15f);
  EXPECT_EQ(paper.background.hidden_width, 128);
  EXPECT_EQ(paper.background.lr_image, 1e-3f);
  // The defaults docs/METHOD.md §7 documents.
  const TrainConfig def = preset_config("default");
  EXPECT_TRUE(def.densify.stats.normalize_each_step);
  EXPECT_FALSE(def.densify.stats.visible_count_from_one);
  EXPECT_TRUE(def.densify.split_screen_needs_grad);
  EXPECT_EQ(def.distractors.pixels_per_distractor, 6);
  EXPECT_FALSE(def.distractors.count_connected_misses);
  EXPECT_FALSE(def.densify.stats.hide_behind_distractors);
  EXPECT_TRUE(def.densify.stats.gradient_per_seen_pixel);
  EXPECT_EQ(def.appearance.lr_image, def.appearance.test_lr);   // one rate: training and the test fit
  EXPECT_EQ(def.background.lr_image, def.appearance.lr_image);  // an own copy trains as the shared one
  EXPECT_EQ(def.distractors.lambda_explained, 0.05f);
  EXPECT_EQ(def.distractors.lambda_mask_tv, 0.1f);
  EXPECT_EQ(def.distractors.lambda_occluder_colour, 0.4f);  // half the L1 weight 0.8
  EXPECT_TRUE(def.distractors.reseed_starved_views);
  EXPECT_TRUE(def.distractors.seed_uncovered);
  EXPECT_EQ(def.distractors.grow_after, 0);
  EXPECT_EQ(def.distractors.lambda_owned, 0.2f);
  EXPECT_EQ(def.distractors.owned_after, def.resolution_schedule);  // the first resolution switch
  EXPECT_EQ(def.distractors.seed_after, def.resolution_schedule);   // from the first resolution switch on
  EXPECT_TRUE(def.distractors.seed_waits_after_reset);
  EXPECT_EQ(def.distractors.min_blend_weight, 0.0f);  // the idle cull, off
  EXPECT_EQ(def.distractors.max_alpha_sum, 2.3f);     // ≈ ln 10
  EXPECT_EQ(def.distractors.refine_every_epochs, 3);
  EXPECT_EQ(def.transient_points.action, TransientPointAction::drop);
  EXPECT_EQ(def.transient_points.min_track_images, 3);
  EXPECT_EQ(def.transient_points.color_tolerance, 0.25f);
  EXPECT_EQ(def.appearance.hidden_width, 32);
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

}  // namespace
}  // namespace desplat
