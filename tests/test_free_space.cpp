// The camera-path cull (train/free_space.hpp): distances and depths against hand-computed
// values and a brute-force reference, and the trainer removing a floater planted on the path.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <Eigen/Dense>

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

// `count` cameras on a rising spiral before 50 random points about z = 4: the path the
// brute-force tests judge Gaussians against.
CameraPath spiral_path(int count, const CameraPathSettings& s, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<Camera> cams;
  for (int i = 0; i < count; ++i) cams.push_back(camera_at(0.1 * i * std::cos(i), 0.1 * i * std::sin(i), 0.05 * i));
  std::vector<std::array<float, 3>> points;
  for (int i = 0; i < 50; ++i) points.push_back({u(rng), u(rng), 4 + u(rng)});
  return camera_path(cams, points, s);
}

TEST(FreeSpace, DistanceToASegmentByHand) {
  const std::array<double, 3> a{0, 0, 0}, b{2, 0, 0};
  EXPECT_DOUBLE_EQ(distance_to_segment({1, 1, 0}, a, b), 1.0);             // beside the middle
  EXPECT_DOUBLE_EQ(distance_to_segment({3, 1, 0}, a, b), std::sqrt(2.0));  // past the end: to b
  EXPECT_DOUBLE_EQ(distance_to_segment({-3, 0, 4}, a, b), 5.0);            // before the start: to a
  EXPECT_DOUBLE_EQ(distance_to_segment({0, 3, 4}, a, a), 5.0);             // a point segment
}

// Σ + r²·I is diagonal in the Gaussian's frame, so the distance is worked out by hand: a
// Gaussian at (0, 0.3, 0) beside the segment from (−1, 0, 0) to (1, 0, 0), long along x.
TEST(FreeSpace, TubeMahalanobisByHand) {
  const std::array<double, 3> a{-1, 0, 0}, b{1, 0, 0};
  const double r = 0.1;
  const float log_scale[3] = {std::log(0.5f), std::log(0.02f), std::log(0.03f)};
  const float identity[4] = {1, 0, 0, 0};
  const double sx2 = 0.25, sy2 = 0.02 * 0.02;
  // The scales arrive as float logarithms: 1e-6 relative is their rounding, not slack.
  const auto near = [](double got, double want) { EXPECT_NEAR(got, want, 1e-6 * want); };
  // Beside the middle: the closest point is straight across, along the short y axis.
  near(tube_mahalanobis2({0, 0.3, 0}, a, b, log_scale, identity, r), 0.09 / (sy2 + r * r));
  // The same Gaussian turned 90° about z: its long axis now points at the segment.
  const float turned[4] = {float(std::cos(M_PI / 4)), 0, 0, float(std::sin(M_PI / 4))};
  near(tube_mahalanobis2({0, 0.3, 0}, a, b, log_scale, turned, r), 0.09 / (sx2 + r * r));
  // Past the end, on the axis: the closest point is b, 1 away along the long axis.
  near(tube_mahalanobis2({2, 0, 0}, a, b, log_scale, identity, r), 1.0 / (sx2 + r * r));
  // A quaternion need not be normalized.
  const float scaled[4] = {2 * turned[0], 0, 0, 2 * turned[3]};
  near(tube_mahalanobis2({0, 0.3, 0}, a, b, log_scale, scaled, r), 0.09 / (sx2 + r * r));
  // A vanishing Gaussian is the centre rule: distance² / r².
  const float tiny[3] = {-30, -30, -30};
  near(tube_mahalanobis2({0.5, 0.3, 0.4}, a, b, tiny, turned, r), 0.25 / (r * r));
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
  s.by_extent = false;  // the centre rule
  s.blind_gap = 0;      // the tube alone
  s.radius = 0.05f, s.max_segment = 0.5f;
  const CameraPath path = camera_path(cams, points, s);
  EXPECT_NEAR(path.median_depth, 10.0, 1e-9);
  EXPECT_NEAR(path.radius, 0.5, 1e-7);
  ASSERT_EQ(path.from.size(), 2u);  // 0→4 and 30→33; 4→30 is 26 > 5
  EXPECT_EQ(path.skipped_segments, 1u);
  EXPECT_EQ(path.from[1][0], 30.0);
  // Centres: on the first segment, just inside and just outside its radius, on the skipped
  // step, past the first segment's end, on the second segment.
  const std::vector<float> means{2, 0.49f, 0, 2, 0.51f, 0, 15, 0, 0, 4.3f, 0.3f, 0, 31, 0, -0.2f};
  const std::vector<uint8_t> on = on_camera_path(path, means);
  EXPECT_EQ(on, (std::vector<uint8_t>{1, 0, 0, 1, 1}));  // (4.3, 0.3): √(0.09 + 0.09) ≈ 0.42 from (4, 0, 0)

  s.radius = 0;  // both rules off
  EXPECT_TRUE(camera_path(cams, points, s).empty());
  EXPECT_EQ(on_camera_path(camera_path(cams, points, s), means), std::vector<uint8_t>(5, 0));
  s.radius = 0.05f;
  EXPECT_TRUE(camera_path(cams, {}, s).empty());  // no points: no depth, no rule
}

TEST(FreeSpace, CullMaskMatchesBruteForceOverEverySegment) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  CameraPathSettings s;
  s.by_extent = false;  // the centre rule
  s.blind_gap = 0;      // the tube alone
  s.radius = 0.08f;
  const CameraPath path = spiral_path(20, s, rng);
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

// With by_extent the mask is min over each segment of (x − μ)ᵀ(Σ + r²I)⁻¹(x − μ) ≤ 1, here
// against a brute force that builds Σ with Eigen and samples each segment.
TEST(FreeSpace, ExtentMaskMatchesBruteForceOverEverySegment) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  CameraPathSettings s;
  s.radius = 0.05f;
  s.by_extent = true;
  s.blind_gap = 0;  // the tube alone
  const CameraPath path = spiral_path(12, s, rng);
  ASSERT_FALSE(path.empty());
  ASSERT_TRUE(path.by_extent);
  std::vector<float> means, log_scales, quats;
  for (int i = 0; i < 1500; ++i) {
    means.insert(means.end(), {0.5f * u(rng), 0.5f * u(rng), 0.3f + 0.5f * u(rng)});
    // Needles and discs up to 0.3 long, at any orientation.
    for (int k = 0; k < 3; ++k) log_scales.push_back(std::log(0.3f) + 2.5f * (u(rng) - 1));
    quats.insert(quats.end(), {u(rng), u(rng), u(rng), u(rng)});
  }
  const std::vector<uint8_t> on = on_camera_path(path, means, log_scales, quats);
  CameraPath centre_rule = path;
  centre_rule.by_extent = false;
  const std::vector<uint8_t> by_centre = on_camera_path(centre_rule, means);
  int hits = 0, beyond_centre_rule = 0;
  for (size_t i = 0; i < on.size(); ++i) {
    Eigen::Quaterniond q(quats[4 * i], quats[4 * i + 1], quats[4 * i + 2], quats[4 * i + 3]);
    const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
    Eigen::Vector3d var;
    for (int k = 0; k < 3; ++k) var[k] = std::exp(2.0 * log_scales[3 * i + k]);
    const Eigen::Matrix3d M =
        (R * var.asDiagonal() * R.transpose() + path.radius * path.radius * Eigen::Matrix3d::Identity()).inverse();
    const Eigen::Vector3d p(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    double best = 1e30;
    for (size_t k = 0; k < path.from.size(); ++k) {
      const Eigen::Vector3d a(path.from[k].data()), b(path.to[k].data());
      for (int t = 0; t <= 2000; ++t) {
        const Eigen::Vector3d d = a + (b - a) * (t / 2000.0) - p;
        best = std::min(best, d.dot(M * d));
      }
    }
    if (std::abs(best - 1.0) < 2e-3) continue;  // too close to the border to judge by sampling
    EXPECT_EQ(on[i], best < 1.0 ? 1 : 0) << "Gaussian " << i << " at Mahalanobis² " << best;
    hits += on[i];
    beyond_centre_rule += on[i] && !by_centre[i];
    EXPECT_TRUE(on[i] || !by_centre[i]) << i;  // the centre rule's hits are a subset
  }
  EXPECT_GT(hits, 20);
  EXPECT_LT(hits, 1400);
  EXPECT_GT(beyond_centre_rule, 5);  // the extent reaches the path from outside the tube
  EXPECT_THROW(on_camera_path(path, means), std::invalid_argument);  // extent without scales
}

// A floater planted halfway between two consecutive training cameras goes at the first
// refinement; the scene's Gaussians (all within 0.35 of the origin, cameras at radius 1) stay.
// A needle whose centre lies 2 radii beside the path but which reaches across it (scale 0.2
// along the way to the path) goes too when judged by extent, and stays when judged by centre.
TEST(FreeSpace, TrainerCullsAFloaterOnThePathAtTheFirstRefinement) {
  const TrainingData data = test::synthetic_training_data(16, 64, 48, 5);  // 12 training views
  for (const bool by_extent : {false, true}) {
    SCOPED_TRACE(by_extent ? "by extent" : "by centre");
    TrainConfig cfg = test::short_schedule(30);
    cfg.distractors.enabled = false;
    cfg.densify.warmup = 10;  // refinements at steps 20 and 30 …
    cfg.densify.refine_every = 10;
    cfg.densify.stop_split_at = 0;  // … that cull only: the count moves by culls alone
    cfg.densify.camera_path.by_extent = by_extent;
    cfg.densify.camera_path.blind_gap = 0;  // the tube alone: the needle would be in a blind gap
    Trainer t(data, cfg);
    const CameraPath& path = t.camera_path();
    ASSERT_FALSE(path.empty());
    // Training views 1, 2, 3, 5, 6, 7, 9, …, 15 at radius 1, depth about 1: the 8 steps between
    // neighbours (0.39 apart) are kept, the 3 across a test view (0.77 apart) skipped.
    EXPECT_EQ(path.from.size(), 8u);
    EXPECT_EQ(path.skipped_segments, 3u);
    const auto a = data.train[0].camera.center(), b = data.train[1].camera.center();
    const Eigen::Vector3d mid = 0.5 * (Eigen::Vector3d(a[0], a[1], a[2]) + Eigen::Vector3d(b[0], b[1], b[2]));
    const Eigen::Vector3d inward = -mid.normalized();  // cameras on a circle about the origin
    GaussianSet planted = copy_rows(t.gaussians().params, std::vector<uint8_t>(t.gaussians().size(), 0));
    planted.resize(2);
    const Eigen::Vector3d needle_at = mid + 2 * path.radius * inward;
    // The needle's long axis (local x) turned onto `inward`.
    const Eigen::Quaternionf turn = Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitX(), inward.cast<float>());
    for (int k = 0; k < 3; ++k) {
      planted.means[k] = float(mid[k]), planted.log_scales[k] = std::log(0.02f);
      planted.means[3 + k] = float(needle_at[k]), planted.log_scales[3 + k] = std::log(k == 0 ? 0.2f : 0.01f);
    }
    planted.quats[0] = 1;
    planted.quats[4] = turn.w(), planted.quats[5] = turn.x(), planted.quats[6] = turn.y(), planted.quats[7] = turn.z();
    planted.opacity_logits[0] = planted.opacity_logits[1] = 3.0f;  // opaque: the opacity cull would not take them
    t.mutable_gaussians().append(planted);
    const size_t before = t.gaussians().size();
    auto near_path = [&](double within) {
      int n = 0;
      for (size_t i = 0; i < t.gaussians().size(); ++i) {
        const std::array<double, 3> p{t.gaussians().params.means[3 * i], t.gaussians().params.means[3 * i + 1],
                                      t.gaussians().params.means[3 * i + 2]};
        n += distance_to_segment(p, {a[0], a[1], a[2]}, {b[0], b[1], b[2]}) < within;
      }
      return n;
    };
    EXPECT_EQ(near_path(path.radius), 1);      // the floater
    EXPECT_EQ(near_path(3 * path.radius), 2);  // and the needle
    int64_t on_path = 0, culled = 0;
    while (t.current_step() < 30) {
      const StepStats s = t.step();
      on_path += s.refine.on_camera_path, culled += s.refine.culled;
    }
    const int expected = by_extent ? 2 : 1;
    EXPECT_EQ(near_path(path.radius), 0);
    EXPECT_EQ(near_path(3 * path.radius), 2 - expected);
    EXPECT_EQ(on_path, expected);
    EXPECT_EQ(t.camera_path_culled, expected);
    EXPECT_EQ(int64_t(before - t.gaussians().size()), culled);  // nothing added, culls only
  }
}

// Two cameras 2 apart along x, both looking along +z, each seeing |x − its x| < z / 2: in front
// of the segment between them lies a triangle neither sees, reaching to depth 2.
TEST(FreeSpace, BlindGapByHand) {
  const Camera a = camera_at(0, 0, 0), b = camera_at(2, 0, 0);  // 16 px, fx 16: tan(half fov) = 1/2
  const double gap = 0.5;                                       // within 1 of the segment
  EXPECT_TRUE(in_blind_gap({1, 0, 0.5}, a, b, gap));            // between them, 0.5 ahead
  EXPECT_TRUE(in_blind_gap({1, 0.9, 0.3}, a, b, gap));          // above that: √0.9 ≈ 0.95 from it
  EXPECT_FALSE(in_blind_gap({1, 0, 1.5}, a, b, gap));           // unseen, but 1.5 from the segment
  EXPECT_FALSE(in_blind_gap({1, 0, -0.5}, a, b, gap));          // behind the pair
  EXPECT_FALSE(in_blind_gap({0.2, 0, 0.8}, a, b, gap));         // a sees it (x/z = 1/4)
  EXPECT_FALSE(in_blind_gap({1.7, 0, 0.8}, a, b, gap));         // b sees it ((x − 2)/z = −3/8)
  EXPECT_FALSE(in_blind_gap({1, 0, 0.5}, a, b, 0.2));           // 0.5 from a segment of 2: beyond 0.2 × 2
  EXPECT_TRUE(in_blind_gap({-0.5, 0, 0.3}, a, b, gap));         // past a's side, unseen: 0.58 from a
  EXPECT_FALSE(in_blind_gap({-1.5, 0, 0.1}, a, b, gap));        // 1.5 from a
}

// With both rules on, each Gaussian's verdict against an independent brute force: the closest
// of 2,001 samples along each segment, and projection through K [R | t] with Eigen.
TEST(FreeSpace, TubeAndBlindGapVerdictsMatchBruteForce) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<Camera> cams;
  for (int i = 0; i < 8; ++i) {  // a ring of inward-looking cameras at radius 2 about (0, 0, 4)
    const double angle = 0.3 * i, x = 2 * std::sin(angle), z = 4 - 2 * std::cos(angle);
    Eigen::Matrix3d R_wc;  // columns: the camera's x, y, z axes in the world
    const Eigen::Vector3d forward = Eigen::Vector3d(-x, 0, 4 - z).normalized(), down(0, 1, 0);
    R_wc.col(0) = down.cross(forward), R_wc.col(1) = down, R_wc.col(2) = forward;  // x = y × z
    Camera c;
    c.width = c.height = 16, c.fx = c.fy = 16, c.cx = c.cy = 8;
    const Eigen::Matrix3d R_cw = R_wc.transpose();
    const Eigen::Vector3d t = -R_cw * Eigen::Vector3d(x, 0, z);
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) c.R_cw[3 * r + k] = float(R_cw(r, k));
      c.t_cw[r] = float(t[r]);
    }
    cams.push_back(c);
  }
  const std::vector<std::array<float, 3>> points{{0, 0, 4}, {0.3f, 0.2f, 4.2f}, {-0.2f, 0, 3.9f}};
  CameraPathSettings s;
  s.radius = 0.03f, s.blind_gap = 0.5f, s.max_segment = 0.5f, s.by_extent = false;
  const CameraPath path = camera_path(cams, points, s);
  ASSERT_EQ(path.from.size(), 7u);  // steps of 0.6 < 0.5 × depth 2
  std::vector<float> means;
  for (int i = 0; i < 4000; ++i) {
    const Camera& c = cams[i % 7];
    const auto o = c.center();
    means.insert(means.end(), {o[0] + 0.5f * u(rng), o[1] + 0.4f * u(rng), o[2] + 0.5f * u(rng)});
  }
  const std::vector<uint8_t> verdict = on_camera_path(path, means);
  auto seen_by = [](const Camera& c, const Eigen::Vector3d& p) {
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) R(r, k) = c.R_cw[3 * r + k];
    const Eigen::Vector3d q = R * p + Eigen::Vector3d(c.t_cw[0], c.t_cw[1], c.t_cw[2]);
    const double px = c.fx * q.x() / q.z() + c.cx, py = c.fy * q.y() / q.z() + c.cy;
    return q.z() > 1e-6 && px >= 0 && py >= 0 && px < c.width && py < c.height;
  };
  int counts[3] = {0, 0, 0};
  for (size_t i = 0; i < verdict.size(); ++i) {
    const Eigen::Vector3d p(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    bool tube = false, gap = false, border = false;
    for (size_t k = 0; k < path.from.size(); ++k) {
      const Eigen::Vector3d a(path.from[k].data()), b(path.to[k].data());
      double best = 1e30;
      for (int t = 0; t <= 2000; ++t) best = std::min(best, (a + (b - a) * (t / 2000.0) - p).norm());
      const double reach = path.blind_gap * (b - a).norm();
      border |= std::abs(best - path.radius) < 1e-3 || std::abs(best - reach) < 1e-3;
      tube |= best < path.radius;
      const Eigen::Vector3d ahead =
          Eigen::Vector3d(path.from_camera[k].R_cw[6], path.from_camera[k].R_cw[7], path.from_camera[k].R_cw[8]) +
          Eigen::Vector3d(path.to_camera[k].R_cw[6], path.to_camera[k].R_cw[7], path.to_camera[k].R_cw[8]);
      gap |= best < reach && (p - 0.5 * (a + b)).dot(ahead) > 0 && !seen_by(path.from_camera[k], p) &&
             !seen_by(path.to_camera[k], p);
    }
    if (border) continue;  // too close to a border to judge by sampling
    const int want = tube ? kInTube : gap ? kInBlindGap : kOffPath;
    EXPECT_EQ(int(verdict[i]), want) << "Gaussian " << i;
    ++counts[verdict[i]];
  }
  EXPECT_GT(counts[kInTube], 20);
  EXPECT_GT(counts[kInBlindGap], 20);
  EXPECT_GT(counts[kOffPath], 1000);
}

// A floater planted in the blind gap in front of two consecutive training cameras, beyond the
// tube's radius, goes at the first refinement with the rule on and stays with it off.
TEST(FreeSpace, TrainerCullsAFloaterInABlindGap) {
  const TrainingData data = test::synthetic_training_data(16, 64, 48, 5);
  for (const float blind_gap : {0.5f, 0.0f}) {
    SCOPED_TRACE("blind_gap " + std::to_string(blind_gap));
    TrainConfig cfg = test::short_schedule(30);
    cfg.distractors.enabled = false;
    cfg.densify.warmup = 10;
    cfg.densify.refine_every = 10;
    cfg.densify.stop_split_at = 0;  // culls only
    cfg.densify.camera_path.blind_gap = blind_gap;
    Trainer t(data, cfg);
    const CameraPath& path = t.camera_path();
    ASSERT_FALSE(path.empty());
    const Camera &ca = data.train[0].camera, &cb = data.train[1].camera;
    const auto a = ca.center(), b = cb.center();
    const Eigen::Vector3d A(a[0], a[1], a[2]), B(b[0], b[1], b[2]), mid = 0.5 * (A + B);
    const double step = (B - A).norm();                              // 0.39
    const Eigen::Vector3d at = mid - 0.4 * step * mid.normalized();  // 0.16 inward: cameras circle the origin
    const std::array<float, 3> x{float(at[0]), float(at[1]), float(at[2])};
    ASSERT_EQ(ca.pixel_of(x), -1);  // neither photo sees it …
    ASSERT_EQ(cb.pixel_of(x), -1);
    ASSERT_GT(0.4 * step, 1.5 * path.radius);  // … and the tube does not reach it
    GaussianSet planted = copy_rows(t.gaussians().params, std::vector<uint8_t>(t.gaussians().size(), 0));
    planted.resize(1);
    for (int k = 0; k < 3; ++k) planted.means[k] = x[k], planted.log_scales[k] = std::log(0.02f);
    planted.quats[0] = 1;
    planted.opacity_logits[0] = 3.0f;
    t.mutable_gaussians().append(planted);
    auto planted_left = [&] {  // it may drift a little under training; the scene is ≥ 0.4 away
      for (size_t i = 0; i < t.gaussians().size(); ++i) {
        double d2 = 0;
        for (int k = 0; k < 3; ++k) d2 += std::pow(t.gaussians().params.means[3 * i + k] - x[k], 2);
        if (d2 < 0.02 * 0.02) return true;
      }
      return false;
    };
    ASSERT_TRUE(planted_left());
    while (t.current_step() < 30) t.step();
    EXPECT_EQ(planted_left(), blind_gap == 0);
    EXPECT_EQ(t.camera_path_blind_gap_culled, blind_gap > 0 ? 1 : 0);
  }
}

TEST(FreeSpace, SettingsAreCheckedReadAndOffInThePaperPreset) {
  const auto error = [](const nlohmann::json& j) {
    return testing::error_of<std::invalid_argument>([&] { config_from_json(j); });
  };
  EXPECT_CONTAINS(
      error({{"densify", {{"camera_path_radius", -0.1}}}}),
      "config: densify.camera_path_radius must be a number in [0, 10^18] (0 turns the rule off) (got -0.1)");
  EXPECT_CONTAINS(error({{"densify", {{"camera_path_max_segment", 0}}}}),
                  "config: densify.camera_path_max_segment must be a number in (0, 10^18] (got 0)");
  EXPECT_EQ(config_from_json({{"densify", {{"camera_path_radius", 0.05}}}}).densify.camera_path.radius, 0.05f);
  EXPECT_EQ(preset_config("paper").densify.camera_path.radius, 0.0f);
  EXPECT_EQ(preset_config("paper").densify.camera_path.blind_gap, 0.0f);
  EXPECT_EQ(preset_config("default").densify.camera_path.blind_gap, 0.5f);
  EXPECT_EQ(config_from_json({{"densify", {{"camera_path_blind_gap", 0.25}}}}).densify.camera_path.blind_gap, 0.25f);
  EXPECT_CONTAINS(
      error({{"densify", {{"camera_path_blind_gap", -1}}}}),
      "config: densify.camera_path_blind_gap must be a number in [0, 10^18] (0 turns the rule off) (got -1)");
  EXPECT_EQ(preset_config("default").densify.camera_path.radius, 0.08f);
  EXPECT_FALSE(preset_config("default").densify.camera_path.by_extent);
  EXPECT_TRUE(config_from_json({{"densify", {{"camera_path_by_extent", true}}}}).densify.camera_path.by_extent);
}

}  // namespace
}  // namespace desplat
