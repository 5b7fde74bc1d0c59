// DeSplat on real photos with known distractors, small and fast: the fox capture with
// occluders pasted into half of its training views (desplat_occlude's recipe, as
// data/synthetic/make_fox_occluded.sh), trained at 1/8 resolution for 2,000 steps, DeSplat
// against --static-only at equal steps. The independent expectations are the pasted masks
// and the untouched original photos.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "desplat/composite.hpp"
#include "desplat/mask_metrics.hpp"
#include "desplat/occluders.hpp"
#include "desplat/training_run.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

const fs::path kFox = "/work/shared/data/fox";

// PSNR over the pixels where `mask` > 0.5 (all three channels).
double masked_psnr(const FloatImage& a, const FloatImage& b, const FloatImage& mask) {
  double se = 0;
  size_t n = 0;
  for (size_t p = 0; p < mask.pixels.size(); ++p) {
    if (mask.pixels[p] <= 0.5f) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = double(a.pixels[3 * p + c]) - double(b.pixels[3 * p + c]);
      se += d * d, ++n;
    }
  }
  return n ? -10.0 * std::log10(std::max(se / n, 1e-12)) : 0.0;
}

TEST(DeSplatEvidence, OccludedFoxMasksMatchAndOccludersAreRemovedFromTheStaticScene) {
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
  const Scene clean = load_colmap_scene(kFox, so);
  const TrainingData data = load_training_data(occluded);
  const TrainingData originals = load_training_data(clean);
  ASSERT_EQ(data.train.size(), originals.train.size());

  TrainConfig config;
  config.iterations = 2000;
  config.num_downscales = 0;  // train at 1/8 from the start: 2,000 steps at 1/32 would say little
  config.threads = 0;
  Trainer desplat(data, config);
  config.distractors.enabled = false;
  Trainer static_only(data, config);
  while (desplat.current_step() < config.iterations) desplat.step(), static_only.step();

  // Masks: A_d > 0.5 against the pasted occluders.
  const MaskMetrics masks = evaluate_distractor_masks(desplat, occluded);
  ASSERT_EQ(masks.occluded_views, 22);
  ASSERT_EQ(masks.clean_views, 21);
  std::printf("mean mask IoU %.3f over %d occluded views; clean-view false positives %.4f\n", masks.mean_iou,
              masks.occluded_views, masks.mean_clean_view_false_positive);
  // Floor 0.5: predicting every pixel as distractor scores at most the covered share (≤ 0.25
  // here) and predicting the occluders' bounding boxes about 0.6 for the ellipses and polygons;
  // 0.5 needs the actual shapes over most views.
  EXPECT_GT(masks.mean_iou, 0.5);
  EXPECT_LT(masks.mean_clean_view_false_positive, 0.02);

  // Behind the occluders: DeSplat's static layer shows the scene the original photo shows,
  // where the static-only model has baked part of the occluder in.
  double desplat_behind = 0, static_behind = 0;
  int views = 0;
  for (size_t v = 0; v < data.train.size(); ++v) {
    size_t scene_index = 0;
    while (occluded.views[scene_index].name != data.train[v].name) ++scene_index;
    const FloatImage truth_mask = load_view_mask(occluded, scene_index);
    if (std::none_of(truth_mask.pixels.begin(), truth_mask.pixels.end(), [](float m) { return m > 0.5f; })) continue;
    ASSERT_EQ(originals.train[v].name, data.train[v].name);
    const FloatImage& photo = originals.train[v].image;
    desplat_behind += masked_psnr(desplat.render(data.train[v].camera, config.eval_background), photo, truth_mask);
    static_behind += masked_psnr(static_only.render(data.train[v].camera, config.eval_background), photo, truth_mask);
    ++views;
  }
  desplat_behind /= views, static_behind /= views;
  std::printf("PSNR behind the occluders against the original photos: DeSplat %.2f dB, static-only %.2f dB\n",
              desplat_behind, static_behind);
  EXPECT_GT(desplat_behind, static_behind + 1.0);

  // Test views (clean): reported, not asserted. At this scale DeSplat trails static-only
  // (see the issue note); the paper's regime (30k steps, ~500 px images) is out of reach here.
  auto mean_psnr = [&](const Trainer& t) {
    double s = 0;
    for (const ViewMetrics& m : t.evaluate(data.test)) s += m.psnr;
    return s / data.test.size();
  };
  std::printf("test PSNR: DeSplat %.2f dB, static-only %.2f dB\n", mean_psnr(desplat), mean_psnr(static_only));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace desplat
