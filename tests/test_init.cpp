// Initialization against brute force: k-nearest-neighbour distances and the §5 rules.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/train/init.hpp"

namespace desplat {
namespace {

TEST(Init, KnnDistanceMatchesBruteForce) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<std::array<float, 3>> pts(700);
  for (auto& p : pts) p = {u(rng), u(rng), 0.3f * u(rng)};
  pts[5] = pts[6];  // a duplicate point: distance 0 to its twin
  const std::vector<float> fast = mean_knn_distance(pts, 3);
  for (size_t i = 0; i < pts.size(); ++i) {
    std::vector<double> d;
    for (size_t j = 0; j < pts.size(); ++j) {
      if (j == i) continue;
      double s = 0;
      for (int k = 0; k < 3; ++k) s += double(pts[i][k] - pts[j][k]) * (pts[i][k] - pts[j][k]);
      d.push_back(std::sqrt(s));
    }
    std::partial_sort(d.begin(), d.begin() + 3, d.end());
    EXPECT_NEAR(fast[i], (d[0] + d[1] + d[2]) / 3, 1e-5) << i;
  }
}

TEST(Init, GaussiansFollowReferenceRules) {
  std::vector<std::array<float, 3>> pts = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}, {0, 0, 3}, {1, 1, 1}};
  std::vector<std::array<uint8_t, 3>> rgb = {{0, 128, 255}, {255, 0, 0}, {1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  const GaussianSet g = init_gaussians_from_points(pts, rgb, 3, 11);
  ASSERT_EQ(g.size(), 5u);
  const std::vector<float> knn = mean_knn_distance(pts, 3);
  for (size_t i = 0; i < 5; ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(g.log_scales[3 * i + k], std::log(knn[i]));
    double qn = 0;
    for (int k = 0; k < 4; ++k) qn += double(g.quats[4 * i + k]) * g.quats[4 * i + k];
    EXPECT_NEAR(qn, 1.0, 1e-6);
    EXPECT_NEAR(1 / (1 + std::exp(-g.opacity_logits[i])), 0.1, 1e-6);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(g.colors[48 * i + c] * kShBand0 + 0.5, rgb[i][c] / 255.0, 1e-6);
    for (int k = 3; k < 48; ++k) EXPECT_EQ(g.colors[48 * i + k], 0.0f);
  }
  // Same seed, same Gaussians; another seed, other rotations.
  EXPECT_EQ(init_gaussians_from_points(pts, rgb, 3, 11).quats, g.quats);
  EXPECT_NE(init_gaussians_from_points(pts, rgb, 3, 12).quats, g.quats);
}

}  // namespace
}  // namespace desplat
