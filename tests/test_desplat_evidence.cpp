// DeSplat on real photos with known distractors, small and fast: the fox capture with
// occluders pasted into half of its training views (desplat_occlude's recipe, as
// data/synthetic/make_fox_occluded.sh), trained at 1/8 resolution for 2,000 steps. The
// independent expectation is the pasted masks. The issue also asks for DeSplat's test PSNR
// to beat --static-only at equal steps; at the scales this machine can train it does not
// (README, "DeSplat on real photos with known distractors"), so that is not asserted here.
#include <gtest/gtest.h>

#include <cstdio>

#include "desplat/mask_metrics.hpp"
#include "desplat/occluders.hpp"
#include "desplat/training_run.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

const fs::path kFox = "/work/shared/data/fox";

TEST(DeSplatEvidence, OccludedFoxDistractorMasksMatchThePastedOccluders) {
  const fs::path dir = fs::temp_directory_path() / ("desplat_evidence_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  OccludeOptions o;
  o.data_dir = kFox;
  o.out_dir = dir / "fox_occluded";
  o.fraction = 0.5, o.seed = 1, o.coverage_min = 0.05, o.coverage_max = 0.25;
  occlude_scene(o);

  SceneOptions so;
  so.downscale = 8;
  const Scene occluded = load_colmap_scene(o.out_dir, so);
  const TrainingData data = load_training_data(occluded);

  TrainConfig config;
  config.iterations = 2000;
  config.num_downscales = 0;  // train at 1/8 from the start: 2,000 steps at 1/32 would say little
  config.threads = 0;
  Trainer desplat(data, config);
  while (desplat.current_step() < config.iterations) desplat.step();

  // Masks: A_d > 0.5 against the pasted occluders.
  const MaskMetrics masks = evaluate_distractor_masks(desplat, occluded);
  ASSERT_EQ(masks.occluded_views, 22);
  ASSERT_EQ(masks.clean_views, 21);
  std::printf("mean mask IoU %.3f over %d occluded views; clean-view false positives %.4f\n", masks.mean_iou,
              masks.occluded_views, masks.mean_clean_view_false_positive);
  // Floor 0.5: predicting every pixel as distractor scores at most the covered share (≤ 0.25
  // here), predicting none scores 0; above 0.5 the predicted and pasted regions agree on more
  // than they disagree, on average over the 22 views.
  EXPECT_GT(masks.mean_iou, 0.5);
  // Clean views: a distractor layer that had taken over the static scene would flag much of
  // the image; allow 5 % (stray splats at edges and in regions few views see).
  EXPECT_LT(masks.mean_clean_view_false_positive, 0.05);

  fs::remove_all(dir);
}

}  // namespace
}  // namespace desplat
