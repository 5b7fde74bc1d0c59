// --effects auto's transient probe (train/transient_probe.hpp): the judgement on hand-made
// error and depth maps whose answer is known, and the whole probe on a synthetic capture with
// known transients and on its clean twin.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "desplat/io/scene.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/synth/synth.hpp"
#include "desplat/train/transient_probe.hpp"
#include "support/expect.hpp"

namespace desplat::test {
namespace {
namespace fs = std::filesystem;

// Five cameras looking along +z at a wall at z = 5, centres 0.25 apart along x. With fx = 40
// a wall point moves 40 · 0.25 / 5 = 2 whole pixels from one view to the next, so every pixel
// centre lands on a pixel centre of each neighbour.
constexpr int kW = 40, kH = 30;
constexpr float kWall = 5, kClean = 0.02f, kBad = 0.3f;

std::vector<ProbeView> wall_views() {
  std::vector<ProbeView> views(5);
  for (int k = 0; k < 5; ++k) {
    Camera& c = views[k].camera;
    c.width = kW, c.height = kH, c.fx = c.fy = 40, c.cx = 20, c.cy = 15;
    c.t_cw = {-0.25f * float(k - 2), 0, 0};
    views[k].error.assign(kW * kH, kClean);
    views[k].depth.assign(kW * kH, kWall);
  }
  return views;
}

void paint(ProbeView& v, int x0, int y0, int size, float error) {
  for (int y = y0; y < y0 + size; ++y)
    for (int x = x0; x < x0 + size; ++x) v.error[size_t(y) * kW + x] = error;
}

TEST(TransientProbe, AnAreaOnlyItsViewLeavesUnexplainedIsATransient) {
  std::vector<ProbeView> views = wall_views();
  paint(views[1], 10, 5, 8, kBad);  // two different objects, each in one view
  paint(views[3], 22, 15, 8, kBad);
  const TransientEvidence ev = judge_transients(views);
  EXPECT_EQ(ev.judged_views, 5);
  EXPECT_FLOAT_EQ(ev.view_share[1], 64.0f / (kW * kH));
  EXPECT_FLOAT_EQ(ev.view_share[3], 64.0f / (kW * kH));
  EXPECT_EQ(ev.view_share[0] + ev.view_share[2] + ev.view_share[4], 0.0f);
  EXPECT_EQ(ev.views_with_transients, 2);
  EXPECT_TRUE(ev.transients) << ev.reason;
}

TEST(TransientProbe, MisfitTheNeighboursShareAtTheSameSurfaceIsNot) {
  // The same patch of wall (x from 0 to 0.5, an 8-pixel-wide block) fits badly in every view:
  // fine texture the probe has not fitted, not an object of one photo.
  std::vector<ProbeView> views = wall_views();
  for (int k = 0; k < 5; ++k) paint(views[k], 16 - 2 * (k - 2), 8, 8, kBad);
  const TransientEvidence ev = judge_transients(views);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(ev.view_share[k], 0.0f) << "view " << k;
  EXPECT_FALSE(ev.transients) << ev.reason;
  // Control: the same block in one view only is counted.
  std::vector<ProbeView> one = wall_views();
  paint(one[2], 16, 8, 8, kBad);
  EXPECT_FLOAT_EQ(judge_transients(one).view_share[2], 64.0f / (kW * kH));
}

TEST(TransientProbe, ANeighbourThatSeesANearerSurfaceThereDoesNotJudgeThePoint) {
  std::vector<ProbeView> views = wall_views();
  paint(views[1], 10, 5, 8, kBad);
  paint(views[3], 22, 15, 8, kBad);
  // In every other view, something at depth 2 stands in front of the wall where view 1's
  // block lies (shifted by 2 px per view): no neighbour sees those wall points.
  for (int k : {0, 2, 3, 4})
    for (int y = 5; y < 13; ++y)
      for (int x = 10 - 2 * (k - 1); x < 18 - 2 * (k - 1); ++x) views[k].depth[size_t(y) * kW + x] = 2;
  TransientEvidence ev = judge_transients(views);
  EXPECT_EQ(ev.view_share[1], 0.0f);
  EXPECT_FLOAT_EQ(ev.view_share[3], 64.0f / (kW * kH));
  EXPECT_EQ(ev.views_with_transients, 1);
  EXPECT_FALSE(ev.transients) << "one view is not enough: " << ev.reason;
  // Nor does one that sees a farther surface there (it sees through where view 1's depth puts
  // a surface: the point is not one surface in both).
  std::vector<ProbeView> farther = views;
  for (int k : {0, 2, 3, 4})
    for (int y = 5; y < 13; ++y)
      for (int x = 10 - 2 * (k - 1); x < 18 - 2 * (k - 1); ++x) farther[k].depth[size_t(y) * kW + x] = 8;
  EXPECT_EQ(judge_transients(farther).view_share[1], 0.0f);
  // Control: without the depth test the hidden points are judged, and view 1 counts.
  TransientRules no_occlusion;
  no_occlusion.depth_tolerance = 1e9f;
  ev = judge_transients(views, no_occlusion);
  EXPECT_FLOAT_EQ(ev.view_share[1], 64.0f / (kW * kH));
  EXPECT_TRUE(ev.transients);
}

TEST(TransientProbe, AreasTheSizeOfAProbesOwnMisfitAreNotATransient) {
  // On clean captures a probe leaves view-specific areas of just under 3 % of a frame, in a few
  // views (docs/METHOD.md §10): 5×5 px (2.1 % of 40×30) in three views is no
  // transient, 7×7 px (4.1 %) in the same places is.
  for (const int size : {5, 7}) {
    std::vector<ProbeView> views = wall_views();
    paint(views[1], 4, 4, size, kBad);
    paint(views[2], 18, 18, size, kBad);
    paint(views[3], 30, 6, size, kBad);
    const TransientEvidence ev = judge_transients(views);
    for (int k : {1, 2, 3}) EXPECT_FLOAT_EQ(ev.view_share[k], float(size * size) / (kW * kH)) << "view " << k;
    EXPECT_EQ(ev.views_with_transients, size == 5 ? 0 : 3) << ev.reason;
    EXPECT_EQ(ev.transients, size == 7) << ev.reason;
  }
}

TEST(TransientProbe, ScatteredPixelsAreNotAnObject) {
  std::vector<ProbeView> views = wall_views();
  for (int k : {1, 3})
    for (int y = 10; y < 20; ++y)
      for (int x = 10; x < 20; ++x)
        if ((x + y) % 2 == 0) views[k].error[size_t(y) * kW + x] = kBad;  // 50 isolated pixels
  EXPECT_FALSE(judge_transients(views).transients);
  TransientRules any_area;
  any_area.min_area = 0;
  const TransientEvidence ev = judge_transients(views, any_area);
  EXPECT_FLOAT_EQ(ev.view_share[1], 50.0f / (kW * kH));
  EXPECT_TRUE(ev.transients);
}

TEST(TransientProbe, PixelsWithoutASurfaceOrMaskedAreNotJudged) {
  std::vector<ProbeView> views = wall_views();
  paint(views[1], 10, 5, 8, kBad);
  paint(views[3], 22, 15, 8, kBad);
  std::vector<ProbeView> no_surface = views, masked = views;
  for (int k = 0; k < 5; ++k) std::fill(no_surface[k].depth.begin(), no_surface[k].depth.end(), 0.0f);
  EXPECT_FALSE(judge_transients(no_surface).transients);
  for (int k : {0, 2, 3, 4}) std::fill(masked[k].error.begin(), masked[k].error.end(), -1.0f);  // user masks
  EXPECT_EQ(judge_transients(masked).view_share[1], 0.0f);
}

TEST(TransientProbe, MapsThatDoNotMatchTheirCameraAreRejected) {
  std::vector<ProbeView> views = wall_views();
  views[2].depth.pop_back();
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { judge_transients(views); }), "does not match");
}

TEST(TransientProbe, TheProbeKeepsAtLeastMinProbeSidePixelsOnTheShortSide) {
  EXPECT_EQ(probe_factor(500, 375), 4);  // 93 px
  EXPECT_EQ(probe_factor(131, 235), 2);  // 65 px; at 4 it would be 32
  EXPECT_EQ(probe_factor(160, 120), 2);
  EXPECT_EQ(probe_factor(65, 117), 1);
  EXPECT_EQ(probe_factor(1920, 1080), 4);  // never beyond max_probe_factor
}

// The whole probe on data/synthetic/tiny_tracks.json (80×60, 21 training views, every one
// with 1–2 objects that stay for 4 consecutive views) and on its clean twin (the same scene
// and cameras, clutter ratio 0): transients in the first, none in the second.
TEST(TransientProbe, FindsTheTransientsOfASyntheticCaptureAndNoneInItsCleanTwin) {
  const fs::path dir = fs::temp_directory_path() / ("desplat_probe_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const synth::Description cluttered =
      synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_tracks.json");
  const synth::Description clean =
      synth::apply_description(cluttered, nlohmann::json{{"distractors", {{"clutter_ratio", 0.0}}}}, "test");
  TrainConfig config;
  config.threads = 2;
  std::vector<TransientEvidence> found;
  for (const synth::Description* d : {&cluttered, &clean}) {
    synth::GenerateOptions g;
    g.out = dir / (d == &clean ? "clean" : "cluttered");
    synth::generate_scene(*d, g);
    const TrainingData data = load_training_data(load_colmap_scene(g.out, SceneOptions{}));
    ASSERT_EQ(data.train.size(), 21u);
    found.push_back(probe_transients(data, config).value());
    if (d == &clean) {
      // A Ctrl-C before or during the probe ends it without an answer.
      const std::atomic<bool> stop{true};
      EXPECT_FALSE(probe_transients(data, config, {}, &stop).has_value());
    }
  }
  fs::remove_all(dir);
  std::printf("cluttered: %s\nclean: %s\n", found[0].reason.c_str(), found[1].reason.c_str());
  EXPECT_TRUE(found[0].transients) << found[0].reason;
  EXPECT_FALSE(found[1].transients) << found[1].reason;
  EXPECT_GT(found[0].views_with_transients, found[1].views_with_transients + 4)
      << found[0].reason << " / " << found[1].reason;
}

}  // namespace
}  // namespace desplat::test
