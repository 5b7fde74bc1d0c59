// The camera-path cull (train/free_space.hpp): distances and depths against hand-computed
// values and a brute-force reference, and the trainer removing a floater planted on the path.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "desplat/train/free_space.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "support/expect.hpp"
#include "support/synthetic_views.hpp"

namespace desplat {
namespace {

// A camera at `center` looking along +z (identity rotation): depth = z − center.z.
Camera camera_at(double x, double y, double z) {
  Camera c;
  c.width = c.height = 16;
  c.fx = c.fy = 16, c.cx = c.cy = 8;
  c.t_cw = {float(-x), float(-y), float(-z)};
  return c;
}

TEST(FreeSpace, DistanceToASegmentByHand) {
  const std::array<double, 3> a{0, 0, 0}, b{2, 0, 0};
  EXPECT_DOUBLE_EQ(distance_to_segment({1, 1, 0}, a, b), 1.0);           // beside the middle
  EXPECT_DOUBLE_EQ(distance_to_segment({3, 1, 0}, a, b), std::sqrt(2.0));  // past the end: to b
  EXPECT_DOUBLE_EQ(distance_to_segment({-3, 0, 4}, a, b), 5.0);            // before the start: to a
  EXPECT_DOUBLE_EQ(distance_to_segment({0, 3, 4}, a, a), 5.0);             // a point segment
}

TEST(FreeSpace, MedianSceneDepthIsTheMedianOverCamerasOfEachCamerasMedian) {
  // Points at z = 1, 2, 3, 10 and one behind every camera (z = −5).
  const std::vector<std::array<float, 3>> points{{0, 0, 1}, {0, 0, 2}, {0, 0, 3}, {0, 0, 10}, {0, 0, -5}};
  // Camera at z = 0: depths 1, 2, 3, 10 → 3 (the upper middle). At z = 1.5: 0.5, 1.5, 8.5 → 1.5.
  // At z = 20: nothing in front, left out. Median of {3, 1.5}: 3 (the upper middle).
  EXPECT_DOUBLE_EQ(median_scene_depth({camera_at(0, 0, 0)}, points), 3.0);
  EXPECT_DOUBLE_EQ(median_scene_depth({camera_at(0, 0, 1.5)}, points), 1.5);
  EXPECT_DOUBLE_EQ(median_scene_depth({camera_at(0, 0, 0), camera_at(0, 0, 1.5), camera_at(0, 0, 20)}, points), 3.0);
  EXPECT_EQ(median_scene_depth({camera_at(0, 0, 20)}, points), 0.0);
  EXPECT_EQ(median_scene_depth({camera_at(0, 0, 0)}, {}), 0.0);
}

TEST(FreeSpace, PathKeepsShortStepsBetweenConsecutiveCamerasOnly) {
  // Every camera sees points at depth 10 (median depth 10): radius 0.5, longest step 5.
  const std::vector<std::array<float, 3>> points{{0, 0, 10}, {4, 0, 10}, {9, 0, 10}, {30, 0, 10}};
  const std::vector<Camera> cams{camera_at(0, 0, 0), camera_at(4, 0, 0), camera_at(30, 0, 0), camera_at(33, 0, 0)};
  CameraPathSettings s;
  s.radius = 0.05f, s.max_segment = 0.5f;
  const CameraPath path = camera_path(cams, points, s);
  EXPECT_NEAR(path.median_depth, 10.0, 1e-9);
  EXPECT_NEAR(path.radius, 0.5, 1e-7);
  ASSERT_EQ(path.from.size(), 2u);  // 0→4 and 30→33; 4→30 is 26 > 5
  EXPECT_EQ(path.skipped_segments, 1u);
  EXPECT_EQ(path.from[1][0], 30.0);
  // Centres: on the first segment, just inside and just outside its radius, on the skipped
  // step, past the first segment's end, on the second segment.
  const std::vector<float> means{2, 0.49f, 0,  2, 0.51f, 0,  15, 0, 0,  4.3f, 0.3f, 0,  31, 0, -0.2f};
  const std::vector<uint8_t> on = on_camera_path(path, means);
  EXPECT_EQ(on, (std::vector<uint8_t>{1, 0, 0, 1, 1}));  // (4.3, 0.3): √(0.09 + 0.09) ≈ 0.42 from (4, 0, 0)

  s.radius = 0;  // off
  EXPECT_TRUE(camera_path(cams, points, s).empty());
  EXPECT_EQ(on_camera_path(camera_path(cams, points, s), means), std::vector<uint8_t>(5, 0));
  s.radius = 0.05f;
  EXPECT_TRUE(camera_path(cams, {}, s).empty());  // no points: no depth, no rule
}

TEST(FreeSpace, CullMaskMatchesBruteForceOverEverySegment) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<Camera> cams;
  for (int i = 0; i < 20; ++i) cams.push_back(camera_at(0.1 * i * std::cos(i), 0.1 * i * std::sin(i), 0.05 * i));
  std::vector<std::array<float, 3>> points;
  for (int i = 0; i < 50; ++i) points.push_back({u(rng), u(rng), 4 + u(rng)});
  CameraPathSettings s;
  s.radius = 0.08f;
  const CameraPath path = camera_path(cams, points, s);
  ASSERT_FALSE(path.empty());
  std::vector<float> means;
  for (int i = 0; i < 3000; ++i) means.insert(means.end(), {0.4f * u(rng), 0.4f * u(rng), 0.6f + 0.6f * u(rng)});
  const std::vector<uint8_t> on = on_camera_path(path, means);
  int hits = 0;
  for (size_t i = 0; i < on.size(); ++i) {
    const std::array<double, 3> p{means[3 * i], means[3 * i + 1], means[3 * i + 2]};
    double best = 1e30;
    for (size_t k = 0; k < path.from.size(); ++k) {
      // Brute force: the closest of 2,001 points along the segment (spacing ≤ 0.0003).
      for (int t = 0; t <= 2000; ++t) {
        double d2 = 0;
        for (int c = 0; c < 3; ++c) {
          const double x = path.from[k][c] + (path.to[k][c] - path.from[k][c]) * t / 2000.0;
          d2 += (p[c] - x) * (p[c] - x);
        }
        best = std::min(best, std::sqrt(d2));
      }
    }
    if (std::abs(best - path.radius) < 1e-3) continue;  // too close to the border to judge by sampling
    EXPECT_EQ(on[i], best < path.radius ? 1 : 0) << "Gaussian " << i << " at distance " << best;
    hits += on[i];
  }
  EXPECT_GT(hits, 20);
  EXPECT_LT(hits, 2900);
}

// A floater planted halfway between two consecutive training cameras goes at the first
// refinement; the scene's Gaussians (all within 0.35 of the origin, cameras at radius 1) stay.
TEST(FreeSpace, TrainerCullsAFloaterOnThePathAtTheFirstRefinement) {
  const TrainingData data = test::synthetic_training_data(16, 64, 48, 5);  // 12 training views
  TrainConfig cfg = test::short_schedule(30);
  cfg.distractors.enabled = false;
  cfg.densify.warmup = 10;        // refinements at steps 20 and 30 …
  cfg.densify.refine_every = 10;
  cfg.densify.stop_split_at = 0;  // … that cull only: the count moves by culls alone
  Trainer t(data, cfg);
  const CameraPath& path = t.camera_path();
  ASSERT_FALSE(path.empty());
  // Training views 1, 2, 3, 5, 6, 7, 9, …, 15 at radius 1, depth about 1: the 8 steps between
  // neighbours (0.39 apart) are kept, the 3 across a test view (0.77 apart) skipped.
  EXPECT_EQ(path.from.size(), 8u);
  EXPECT_EQ(path.skipped_segments, 3u);
  const auto a = data.train[0].camera.center(), b = data.train[1].camera.center();
  GaussianSet floater = copy_rows(t.gaussians().params, std::vector<uint8_t>(t.gaussians().size(), 0));
  floater.resize(1);
  for (int k = 0; k < 3; ++k) floater.means[k] = 0.5f * (a[k] + b[k]), floater.log_scales[k] = std::log(0.02f);
  floater.quats[0] = 1;
  floater.opacity_logits[0] = 3.0f;  // opaque: the opacity cull would not take it
  t.mutable_gaussians().append(floater);
  const size_t before = t.gaussians().size();
  auto floaters = [&] {
    int n = 0;
    for (size_t i = 0; i < t.gaussians().size(); ++i) {
      const std::array<double, 3> p{t.gaussians().params.means[3 * i], t.gaussians().params.means[3 * i + 1],
                                    t.gaussians().params.means[3 * i + 2]};
      n += distance_to_segment(p, {a[0], a[1], a[2]}, {b[0], b[1], b[2]}) < path.radius;
    }
    return n;
  };
  EXPECT_EQ(floaters(), 1);
  int64_t on_path = 0, culled = 0;
  while (t.current_step() < 30) {
    const StepStats s = t.step();
    on_path += s.refine.on_camera_path, culled += s.refine.culled;
  }
  EXPECT_EQ(floaters(), 0);
  EXPECT_EQ(on_path, 1);
  EXPECT_EQ(t.camera_path_culled, 1);
  EXPECT_EQ(int64_t(before - t.gaussians().size()), culled);  // nothing added, culls only
}

TEST(FreeSpace, SettingsAreCheckedReadAndOffInThePaperPreset) {
  const auto error = [](const nlohmann::json& j) {
    return testing::error_of<std::invalid_argument>([&] { config_from_json(j); });
  };
  EXPECT_CONTAINS(error({{"densify", {{"camera_path_radius", -0.1}}}}),
                  "config: densify.camera_path_radius must be ≥ 0 (0 turns the rule off) (got -0.1)");
  EXPECT_CONTAINS(error({{"densify", {{"camera_path_max_segment", 0}}}}),
                  "config: densify.camera_path_max_segment must be > 0 (got 0)");
  EXPECT_EQ(config_from_json({{"densify", {{"camera_path_radius", 0.05}}}}).densify.camera_path.radius, 0.05f);
  EXPECT_EQ(preset_config("paper").densify.camera_path.radius, 0.0f);
  EXPECT_EQ(preset_config("default").densify.camera_path.radius, 0.08f);
}

}  // namespace
}  // namespace desplat
