// Adaptive density control on hand-built Gaussians whose fate docs/METHOD.md §7 decides.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "desplat/train/density.hpp"

namespace desplat {
namespace {

float logit(float p) { return std::log(p / (1 - p)); }

// Gaussian i: log-scale from `scale`, opacity, and statistics giving mean grad `grad` over 4
// visible steps, each already normalized by its image size (the default StatisticsRules).
struct Spec {
  float scale, opacity, grad, screen;
};

TrainableGaussians build(const std::vector<Spec>& specs) {
  GaussianSet g;
  g.sh_degree = 1;
  g.feature_dim = 2;  // appearance features ride along with every copy
  g.resize(specs.size());
  for (size_t i = 0; i < specs.size(); ++i) {
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = float(i) + 0.1f * k;
    g.log_scales[3 * i] = std::log(specs[i].scale);
    g.log_scales[3 * i + 1] = g.log_scales[3 * i + 2] = std::log(specs[i].scale * 0.5f);
    g.quats[4 * i] = 1;
    g.opacity_logits[i] = logit(specs[i].opacity);
    for (int k = 0; k < 12; ++k) g.colors[12 * i + k] = float(i) + 0.01f * k;
    for (int k = 0; k < 2; ++k) g.features[2 * i + k] = float(i) + 0.5f * k;
  }
  TrainableGaussians t(g);
  for (size_t i = 0; i < specs.size(); ++i) {
    t.visible_count[i] = 4;
    t.absgrad_sum[i] = specs[i].grad * 4;
    t.max_screen_radius[i] = specs[i].screen;
    for (int gr = 0; gr < kParamGroups; ++gr) std::fill(t.adam_m[gr].begin(), t.adam_m[gr].end(), 1.0f);
  }
  return t;
}

TEST(Density, SplitDuplicateCullDuringDensification) {
  TrainableGaussians t = build({
      {0.05f, 0.5f, 0.002f, 0.01f},    // 0: high grad, large → split
      {0.005f, 0.5f, 0.002f, 0.01f},   // 1: high grad, small → duplicate
      {0.05f, 0.5f, 0.0001f, 0.01f},   // 2: low grad → stays
      {0.05f, 0.05f, 0.0001f, 0.01f},  // 3: opacity below 0.1 → culled
      {0.005f, 0.5f, 0.002f, 0.06f},   // 4: small but big on screen (step < 4000) → split, and duplicated
      {0.015f, 0.5f, 0.002f, 0.01f},   // 5: large → split; 0.015/1.6 ≤ 0.01 → also duplicated
  });
  std::mt19937_64 rng(1);
  const RefineReport r = refine_gaussians(t, DensifySettings{}, 700, 100, 10, rng);
  ASSERT_TRUE(r.ran);
  EXPECT_EQ(r.split, 3);
  EXPECT_EQ(r.duplicated, 3);
  EXPECT_EQ(r.culled, 1);
  // Rows: survivors (1, 2); split children sample-major (0, 4, 5, 0, 4, 5); duplicates (1, 4, 5).
  ASSERT_EQ(t.size(), 11u);
  t.check_consistent();
  EXPECT_EQ(t.params.means[0], 1.0f);
  EXPECT_EQ(t.params.means[3], 2.0f);
  const int parents[6] = {0, 4, 5, 0, 4, 5};
  const float parent_scale[6] = {0.05f, 0.005f, 0.015f, 0.05f, 0.005f, 0.015f};
  for (int c = 0; c < 6; ++c) {
    const size_t i = 2 + c;
    EXPECT_NEAR(std::exp(t.params.log_scales[3 * i]), parent_scale[c] / 1.6f, 1e-6f);
    EXPECT_NEAR(t.params.means[3 * i], float(parents[c]), 6 * parent_scale[c]);  // a draw from the parent
    EXPECT_EQ(t.params.colors[12 * i], float(parents[c]));
    EXPECT_EQ(t.params.features[2 * i + 1], float(parents[c]) + 0.5f);
    for (int gr = 0; gr < kParamGroups; ++gr) EXPECT_EQ(t.adam_m[gr][i * t.floats_per_gaussian(ParamGroup(gr))], 0.0f);
  }
  const int dup_parents[3] = {1, 4, 5};
  const float dup_scale[3] = {0.005f, 0.005f / 1.6f, 0.015f / 1.6f};  // split originals shrank first
  for (int d = 0; d < 3; ++d) {
    const size_t i = 8 + d;
    EXPECT_EQ(t.params.means[3 * i], float(dup_parents[d]));  // exact copy of the position
    EXPECT_EQ(t.params.features[2 * i], float(dup_parents[d]));
    EXPECT_NEAR(std::exp(t.params.log_scales[3 * i]), dup_scale[d], 1e-6f);
  }
  EXPECT_EQ(t.adam_m[0][0], 1.0f);                    // survivors keep their moments
  for (int32_t v : t.visible_count) EXPECT_EQ(v, 0);  // statistics restart
}

TEST(Density, NoDensificationRightAfterAReset) {
  // 3100 % 3000 = 100 ≤ 10 views + 100: only cull (and the opacity reset).
  TrainableGaussians t = build({{0.05f, 0.5f, 0.002f, 0.01f}, {0.005f, 0.5f, 0.002f, 0.01f}});
  std::mt19937_64 rng(1);
  const RefineReport r = refine_gaussians(t, DensifySettings{}, 3100, 100, 10, rng);
  EXPECT_EQ(r.split + r.duplicated, 0);
  EXPECT_TRUE(r.opacity_reset);
  for (float l : t.params.opacity_logits) EXPECT_NEAR(l, logit(0.2f), 1e-6f);
  for (float m : t.adam_m[int(ParamGroup::OpacityLogits)]) EXPECT_EQ(m, 0.0f);
  EXPECT_EQ(t.adam_m[int(ParamGroup::Means)][0], 1.0f);  // other groups keep theirs
}

TEST(Density, SizeCullsOnlyAfterTheFirstReset) {
  const std::vector<Spec> specs = {{0.8f, 0.5f, 0.0f, 0.01f}, {0.05f, 0.5f, 0.0f, 0.2f}, {0.05f, 0.5f, 0.0f, 0.01f}};
  std::mt19937_64 rng(1);
  TrainableGaussians early = build(specs);
  EXPECT_EQ(refine_gaussians(early, DensifySettings{}, 2900, 100, 10, rng).culled, 0);
  TrainableGaussians later = build(specs);
  EXPECT_EQ(refine_gaussians(later, DensifySettings{}, 3200, 100, 10, rng).culled, 2);  // too big in world, on screen
  TrainableGaussians after_screen = build(specs);
  EXPECT_EQ(refine_gaussians(after_screen, DensifySettings{}, 4100, 100, 10, rng).culled, 1);  // screen rule over
  TrainableGaussians post = build({{0.05f, 0.05f, 0.002f, 0.01f}, {0.05f, 0.5f, 0.002f, 0.01f}});
  const RefineReport r = refine_gaussians(post, DensifySettings{}, 16000, 100, 10, rng);  // cull only
  EXPECT_EQ(r.culled, 1);
  EXPECT_EQ(r.split, 0);
  EXPECT_FALSE(r.opacity_reset);
}

TEST(Density, NothingBeforeWarmupOrBetweenRefinements) {
  TrainableGaussians t = build({{0.05f, 0.05f, 0.002f, 0.01f}});
  std::mt19937_64 rng(1);
  EXPECT_FALSE(refine_gaussians(t, DensifySettings{}, 500, 100, 10, rng).ran);
  EXPECT_FALSE(refine_gaussians(t, DensifySettings{}, 650, 100, 10, rng).ran);
  EXPECT_EQ(t.size(), 1u);
}

// Split children are draws from the parent: their empirical covariance matches Σ.
TEST(Density, SplitSamplesFollowTheParentCovariance) {
  GaussianSet g;
  g.sh_degree = 0;
  g.resize(1);
  g.log_scales = {std::log(0.3f), std::log(0.1f), std::log(0.02f)};
  g.quats = {0.8f, 0.2f, -0.4f, 0.1f};
  std::mt19937_64 rng(5);
  const int n = 4000;
  const GaussianSet s = split_samples(g, {1}, n, 1.6f, rng);
  ASSERT_EQ(s.size(), size_t(n));
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d x(s.means[3 * i], s.means[3 * i + 1], s.means[3 * i + 2]);
    cov += x * x.transpose() / n;
  }
  const Eigen::Matrix3d R = Eigen::Quaterniond(0.8, 0.2, -0.4, 0.1).normalized().toRotationMatrix();
  const Eigen::Matrix3d want = R * Eigen::Vector3d(0.09, 0.01, 0.0004).asDiagonal() * R.transpose();
  // 4000 draws: each covariance entry has a standard error of about sqrt(2/4000)·0.09 ≈ 0.002.
  EXPECT_LT((cov - want).cwiseAbs().maxCoeff(), 0.01);
}

}  // namespace
}  // namespace desplat
