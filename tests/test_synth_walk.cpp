// The synthetic generator's forward walk (views.path "walk", src/synth/camera_path.hpp): the
// cameras move along a straight line, each looking along the direction of walking, with the
// sway and bob the description asks for, deterministic in the seed; the street scene's
// description meets what the forward-walk SfM test needs of it.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <numbers>

#include "desplat/synth/synth.hpp"
#include "synth/camera_path.hpp"

namespace desplat::testing {
namespace {

TEST(SynthWalk, CamerasWalkStraightAheadLookingAlongTheWalk) {
  synth::ViewsSpec v;
  v.path = "walk";
  v.count = 9;
  v.target = {1, 2, 0};
  v.radius = 8;
  v.height = 1.5;
  v.start_deg = 30;
  v.spread = {0.1, 0.02};
  const std::vector<synth::ViewPose> poses = synth::camera_path(v, 5);
  ASSERT_EQ(poses.size(), 9u);
  const double a = 30 * std::numbers::pi / 180;
  const Eigen::Vector3d heading(std::cos(a), std::sin(a), 0), left(-std::sin(a), std::cos(a), 0);
  for (int k = 0; k < 9; ++k) {
    const synth::ViewPose& p = poses[size_t(k)];
    // Looking along the walk, level (the camera's z row is the heading, its y row points down).
    EXPECT_LT((p.R_cw.row(2).transpose() - heading).norm(), 1e-12) << k;
    EXPECT_LT((p.R_cw.row(1).transpose() - Eigen::Vector3d(0, 0, -1)).norm(), 1e-12) << k;
    EXPECT_LT((p.R_cw * p.center + p.t_cw).norm(), 1e-12) << k;
    // On the line through the point `height` above the target, from −radius/2 to +radius/2,
    // off it by the sway (sideways) and the bob (up) only.
    const Eigen::Vector3d off = p.center - Eigen::Vector3d(1, 2, 1.5);
    EXPECT_NEAR(off.dot(heading), (k / 8.0 - 0.5) * 8, 1e-12) << k;
    EXPECT_NEAR(off.dot(left), 0.1 * std::sin(6 * std::numbers::pi * k / 8.0), 1e-12) << k;
    EXPECT_NEAR(off.z(), 0.02 * std::sin(0.5 * std::numbers::pi * k), 1e-12) << k;
    // The point it looks at lies radius ahead: distractors' depth scales with it.
    EXPECT_NEAR((p.target - p.center).norm(), 8, 1e-12) << k;
  }
  // Jitter moves each centre by at most its bound, the same way for the same seed.
  v.position_jitter = 0.05;
  const std::vector<synth::ViewPose> j1 = synth::camera_path(v, 5), j2 = synth::camera_path(v, 5);
  for (size_t k = 0; k < poses.size(); ++k) {
    EXPECT_EQ(j1[k].center, j2[k].center);
    EXPECT_LE((j1[k].center - poses[k].center).cwiseAbs().maxCoeff(), 0.05);
    EXPECT_GT((j1[k].center - poses[k].center).norm(), 0);
  }
}

TEST(SynthWalk, TheStreetWalkIsAForwardWalkOfThirtyOrMoreViewsAtLeast640By480) {
  const synth::Description d =
      synth::load_description(std::filesystem::path(DESPLAT_SOURCE_DIR) / "data/synthetic/street_walk.json");
  EXPECT_EQ(d.views.path, "walk");
  EXPECT_GE(d.views.count, 30);
  EXPECT_GE(d.camera.width, 640);
  EXPECT_GE(d.camera.height, 480);
  EXPECT_TRUE(d.sky.enabled);
  EXPECT_GT(d.distractors.clutter_ratio, 0);
  // Consecutive views move within 18° of their viewing direction: what colmap's default
  // mapper refuses to start from (Mapper.init_max_forward_motion 0.95).
  const std::vector<synth::ViewPose> poses = synth::camera_path(d.views, d.seed);
  int forward = 0;
  for (size_t k = 1; k < poses.size(); ++k) {
    const Eigen::Vector3d step = (poses[k].center - poses[k - 1].center).normalized();
    forward += std::abs(step.dot(poses[k].R_cw.row(2).transpose())) >= 0.95;
  }
  EXPECT_GE(forward, 0.8 * double(poses.size() - 1));
}

}  // namespace
}  // namespace desplat::testing
