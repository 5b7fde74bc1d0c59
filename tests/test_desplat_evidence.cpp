// DeSplat on real photos with known distractors, small and fast: the fox capture with
// occluders pasted into about half of its training views (desplat_occlude's recipe, as
// data/synthetic/make_fox_occluded.sh with --track 4: each set of occluders stays in the frame
// for 4 consecutive training views, as a hand or a passer-by would), trained at 1/8 resolution
// for 2,000 steps, once as DeSplat with its defaults and once --static-only. The independent
// expectations are the pasted masks and the clean held-out photos.
//
// What is asserted: the static layer scores a higher test PSNR and SSIM than the baseline
// trained on the same occluded photos, the distractor masks match the occluders, and clean
// views stay clean. (With occluders drawn independently for every view the baseline loses
// little to them and DeSplat is level with it; docs/BENCHMARKS.md, the occluded fox.)
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>

#include "desplat/eval/mask_metrics.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/synth/occluders.hpp"
#include "desplat/synth/synth.hpp"
#include "support/fox_scene.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

const fs::path kFox = desplat::testing::fox_dir();

double mean_of(const std::vector<ViewMetrics>& v, double ViewMetrics::*field) {
  double s = 0;
  for (const ViewMetrics& m : v) s += m.*field;
  return s / double(v.size());
}

// DeSplat with `config`, then the same config --static-only, each trained to
// config.iterations. Held by pointer because a Trainer refers to `data`.
struct DeSplatAndBaseline {
  std::unique_ptr<Trainer> desplat, baseline;
};
DeSplatAndBaseline train_both(const TrainingData& data, TrainConfig config) {
  config.distractors.enabled = true;
  auto desplat = std::make_unique<Trainer>(data, config);
  while (desplat->current_step() < config.iterations) desplat->step();
  config.distractors.enabled = false;
  auto baseline = std::make_unique<Trainer>(data, config);
  while (baseline->current_step() < config.iterations) baseline->step();
  return {std::move(desplat), std::move(baseline)};
}

TEST(DeSplatEvidence, OccludedFoxStaticLayerBeatsTheBaselineAndMasksMatchTheOccluders) {
  const fs::path dir = fs::temp_directory_path() / ("desplat_evidence_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  OccludeOptions o;
  o.data_dir = kFox;
  o.out_dir = dir / "fox_occluded";
  o.fraction = 0.5, o.seed = 1, o.coverage_min = 0.05, o.coverage_max = 0.25, o.track_length = 4;
  occlude_scene(o);

  SceneOptions so;
  so.downscale = 8;
  const Scene occluded = load_colmap_scene(o.out_dir, so);
  const TrainingData data = load_training_data(occluded);

  TrainConfig config;
  config.iterations = 2000;
  config.num_downscales = 0;  // train at 1/8 from the start: 2,000 steps at 1/32 would say little
  config.threads = 0;
  // 1,000 · (64·117) / (504·378): the paper's density
  EXPECT_EQ(Trainer(data, config).distractors()[0].size(), 39u);
  const auto [desplat, baseline] = train_both(data, config);

  const std::vector<ViewMetrics> ours = desplat->evaluate(data.test), theirs = baseline->evaluate(data.test);
  const double psnr_ours = mean_of(ours, &ViewMetrics::psnr), psnr_theirs = mean_of(theirs, &ViewMetrics::psnr);
  const double ssim_ours = mean_of(ours, &ViewMetrics::ssim), ssim_theirs = mean_of(theirs, &ViewMetrics::ssim);
  std::printf("test views: DeSplat PSNR %.2f dB SSIM %.4f, static-only PSNR %.2f dB SSIM %.4f\n", psnr_ours, ssim_ours,
              psnr_theirs, ssim_theirs);
  // The direction only, no margin: the measured gap (docs/BENCHMARKS.md) is what the claim rests on.
  EXPECT_GT(psnr_ours, psnr_theirs);
  EXPECT_GT(ssim_ours, ssim_theirs);

  // Masks: A_d > 0.5 against the pasted occluders.
  const MaskMetrics masks = evaluate_distractor_masks(*desplat, occluded);
  ASSERT_EQ(masks.occluded_views, 20);  // 5 tracks of 4: round(0.5 · 43 / 4) = 5
  ASSERT_EQ(masks.clean_views, 23);
  std::printf("mean mask IoU %.3f over %d occluded views; clean-view false positives %.4f\n", masks.mean_iou,
              masks.occluded_views, masks.mean_clean_view_false_positive);
  // Floor 0.5: predicting every pixel as distractor scores at most the covered share (≤ 0.25
  // here), predicting none scores 0; above 0.5 the predicted and pasted regions agree on more
  // than they disagree, on average over the 20 views.
  EXPECT_GT(masks.mean_iou, 0.5);
  // Clean views: a distractor layer that had taken over the static scene would flag much of
  // the image; allow 1 % (stray splats at edges and in regions few views see).
  EXPECT_LT(masks.mean_clean_view_false_positive, 0.01);

  fs::remove_all(dir);
}

// The same comparison on the tiny synthetic scene with known ground truth:
// data/synthetic/tiny_tracks.json, 80×60, 21 training views all cluttered with 1–2 objects
// that stay in the frame for 4 consecutive views, 3 clean test views, 2,000 steps.
TEST(DeSplatEvidence, TinySyntheticSceneStaticLayerBeatsTheBaselineAndMasksMatch) {
  const fs::path dir = fs::temp_directory_path() / ("desplat_evidence_tiny_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  synth::GenerateOptions g;
  g.out = dir / "scene";
  synth::generate_scene(synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_tracks.json"), g);
  const Scene scene = load_colmap_scene(g.out, SceneOptions{});
  const TrainingData data = load_training_data(scene);
  ASSERT_EQ(data.train.size(), 21u);
  ASSERT_EQ(data.test.size(), 3u);

  TrainConfig config;
  config.iterations = 2000;
  config.num_downscales = 0;  // the schedule would keep a 2,000-step run below full resolution
  // Seeding from the warm-up, as --preset fast: the default's wait for step 3,000 is for its
  // own schedule (docs/METHOD.md §7), and a 2,000-step run ends before it (desplat_train warns).
  config.distractors.seed_after = 0;
  config.distractors.seed_waits_after_reset = false;
  const auto [desplat, baseline] = train_both(data, config);

  const std::vector<ViewMetrics> ours = desplat->evaluate(data.test), theirs = baseline->evaluate(data.test);
  const double psnr_ours = mean_of(ours, &ViewMetrics::psnr), psnr_theirs = mean_of(theirs, &ViewMetrics::psnr);
  std::printf("tiny scene test views: DeSplat PSNR %.2f dB SSIM %.4f, static-only PSNR %.2f dB SSIM %.4f\n", psnr_ours,
              mean_of(ours, &ViewMetrics::ssim), psnr_theirs, mean_of(theirs, &ViewMetrics::ssim));
  EXPECT_GT(psnr_ours, psnr_theirs);

  const MaskMetrics masks = evaluate_distractor_masks(*desplat, scene);
  ASSERT_EQ(masks.occluded_views, 21);
  double covered = 0;
  for (const ViewMaskMetrics& v : masks.views) covered += v.score.truth_fraction / double(masks.views.size());
  std::printf("mean mask IoU %.3f; distractors cover %.1f %% of a training view on average\n", masks.mean_iou,
              100 * covered);
  // Floor 0.5 as above; it means something only while marking every pixel would score less.
  ASSERT_LT(covered, 0.5);
  EXPECT_GT(masks.mean_iou, 0.5);

  fs::remove_all(dir);
}

}  // namespace
}  // namespace desplat
