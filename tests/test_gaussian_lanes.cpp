// The vector-lane projection (raster/gaussian_lanes.hpp) against the scalar templates of
// stage_math.hpp evaluated in double precision: the same visibility, the same integer radii
// and the same projected values up to float rounding, on random Gaussians and hard cases.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <random>

#include "raster/gaussian_lanes.hpp"

namespace desplat::raster {
namespace {

struct Reference {
  bool visible;
  double mean2d[2], cov2d[3], conic[3], radius[2];
  double cov_term_scale;  // |J|²·trace(V): the size of the terms cov2d sums, which may cancel
  bool ambiguous;         // a float rounding away from a culling or ceil boundary: skip exact checks
};

// preprocess's rules in double, from the templates.
Reference reference(const LaneCamera& c, const double* mean, const double* log_scale, const double* quat,
                    const PinholeIntrinsics& K) {
  Reference r{};
  Mat3<double> W;
  for (int i = 0; i < 9; ++i) W(i / 3, i % 3) = c.W[i];
  const Vec3<double> p = W * Vec3<double>(mean[0], mean[1], mean[2]) + Vec3<double>(c.t[0], c.t[1], c.t[2]);
  if (!(p[2] > c.near_plane && p[2] < c.far_plane)) return r;
  const Mat3<double> V = W * covariance_3d<double>(log_scale, quat) * W.transpose();
  const Projection<double> proj = project_ewa<double>(p, V, K, c.eps2d);
  double det = 0;
  const Vec3<double> conic = conic_from_cov2d<double>(proj.cov2d, &det);
  const double ex = kExtentSigmas * std::sqrt(proj.cov2d(0, 0)), ey = kExtentSigmas * std::sqrt(proj.cov2d(1, 1));
  auto near_int = [](double v) { return std::abs(v - std::round(v)) < 1e-4 * std::max(1.0, v); };
  const double cond = (proj.cov2d(0, 0) + proj.cov2d(1, 1)) * (proj.cov2d(0, 0) + proj.cov2d(1, 1)) / det;
  r.ambiguous = near_int(ex) || near_int(ey) || (det > 0 && !(cond < 1e4));  // NaN: culled, not ambiguous
  if (!(det > 0) || !conic.allFinite() || !proj.mean2d.allFinite()) return r;
  const double rx = std::min<double>(kMaxRadius, std::ceil(ex)), ry = std::min<double>(kMaxRadius, std::ceil(ey));
  const double mx = proj.mean2d[0], my = proj.mean2d[1];
  for (double edge : {mx + rx, mx - rx - c.width, my + ry, my - ry - c.height})
    if (std::abs(edge) < 1e-3 * std::max(1.0, std::abs(mx) + std::abs(my))) r.ambiguous = true;
  if (!(rx > 0 && ry > 0) || mx + rx <= 0 || mx - rx >= c.width || my + ry <= 0 || my - ry >= c.height) return r;
  r.visible = true;
  const double rz = 1.0 / p[2], jx = K.fx * rz * (1.0 + std::abs(p[0] * rz)),
               jy = K.fy * rz * (1.0 + std::abs(p[1] * rz));
  r.cov_term_scale = std::max(jx * jx, jy * jy) * V.trace() + c.eps2d;
  r.mean2d[0] = mx, r.mean2d[1] = my;
  r.cov2d[0] = proj.cov2d(0, 0), r.cov2d[1] = proj.cov2d(0, 1), r.cov2d[2] = proj.cov2d(1, 1);
  for (int k = 0; k < 3; ++k) r.conic[k] = conic[k];
  r.radius[0] = rx, r.radius[1] = ry;
  return r;
}

// One block's inputs in lanes, from per-Gaussian rows.
LaneGaussians to_lanes(const float (&mean)[kLanes][3], const float (&log_scale)[kLanes][3],
                       const float (&quat)[kLanes][4]) {
  LaneGaussians in;
  for (int l = 0; l < kLanes; ++l) {
    for (int k = 0; k < 3; ++k) in.mean[k][l] = mean[l][k], in.scale[k][l] = std::exp(log_scale[l][k]);
    for (int k = 0; k < 4; ++k) in.quat[k][l] = quat[l][k];
  }
  return in;
}

class Lanes : public ::testing::Test {
 protected:
  const PinholeIntrinsics K{210.0f, 205.0f, 121.0f, 66.5f, 240, 135};
  // A rotated camera, so every entry of W takes part.
  const float R[9] = {0.8660254f, 0.0f, -0.5f, 0.1294095f, 0.9659258f, 0.2241439f, 0.4829629f, -0.2588190f, 0.8365163f};
  const float t[3] = {0.3f, -0.2f, 4.0f};
  const LaneCamera cam{R, t, K, 0.3f, 0.01f, 1e10f};

  // Runs one block through the lanes and compares every lane with the double reference.
  void check_block(const float (&mean)[kLanes][3], const float (&log_scale)[kLanes][3], const float (&quat)[kLanes][4],
                   int* compared) {
    const LaneGaussians in = to_lanes(mean, log_scale, quat);
    LaneGeometry geometry;
    geometry_lanes(cam, in, geometry);
    LaneProjection got;
    project_lanes(cam, in, geometry.V, got);
    for (int l = 0; l < kLanes; ++l) {
      double m[3], s[3], q[4];
      for (int k = 0; k < 3; ++k) m[k] = mean[l][k], s[k] = log_scale[l][k];
      for (int k = 0; k < 4; ++k) q[k] = quat[l][k];
      const Reference want = reference(cam, m, s, q, K);
      if (want.ambiguous) continue;
      ++*compared;
      ASSERT_EQ(bool(got.visible[l]), want.visible) << "lane " << l;
      if (!want.visible) continue;
      for (int k = 0; k < 2; ++k) {
        EXPECT_EQ(got.radius[k][l], want.radius[k]) << "lane " << l;
        EXPECT_NEAR(got.mean2d[k][l], want.mean2d[k], 1e-5 * (std::abs(want.mean2d[k]) + K.width)) << "lane " << l;
      }
      const double cov_scale = want.cov_term_scale;
      const double conic_scale = std::max(want.conic[0], want.conic[2]);
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(got.cov2d[k][l], want.cov2d[k], 1e-5 * cov_scale) << "lane " << l;
        const double cond = (want.cov2d[0] + want.cov2d[2]) * (want.cov2d[0] + want.cov2d[2]) /
                            (want.cov2d[0] * want.cov2d[2] - want.cov2d[1] * want.cov2d[1]);
        EXPECT_NEAR(got.conic[k][l], want.conic[k], 1e-5 * cond * conic_scale) << "lane " << l;
      }
    }
  }
};

TEST_F(Lanes, RandomGaussiansMatchTheDoubleTemplates) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> xy(-5.0f, 5.0f), zr(-2.0f, 6.0f), ls(-6.0f, 1.5f), qn(-1.0f, 1.0f);
  int compared = 0, visible = 0;
  for (int block = 0; block < 400; ++block) {
    float mean[kLanes][3], log_scale[kLanes][3], quat[kLanes][4];
    for (int l = 0; l < kLanes; ++l) {
      mean[l][0] = xy(rng), mean[l][1] = xy(rng), mean[l][2] = zr(rng);
      for (float& v : log_scale[l]) v = ls(rng);
      for (float& v : quat[l]) v = qn(rng);
    }
    check_block(mean, log_scale, quat, &compared);
    for (int l = 0; l < kLanes; ++l) {
      double m[3] = {mean[l][0], mean[l][1], mean[l][2]}, s[3] = {log_scale[l][0], log_scale[l][1], log_scale[l][2]};
      double q[4] = {quat[l][0], quat[l][1], quat[l][2], quat[l][3]};
      visible += reference(cam, m, s, q, K).visible;
    }
  }
  // Most lanes are compared, and both outcomes occur often.
  EXPECT_GT(compared, 400 * kLanes * 9 / 10);
  EXPECT_GT(visible, 400 * kLanes / 5);
  EXPECT_LT(visible, 400 * kLanes * 4 / 5);
}

TEST_F(Lanes, HardCasesFollowTheScalarRules) {
  float mean[kLanes][3], log_scale[kLanes][3], quat[kLanes][4];
  for (int l = 0; l < kLanes; ++l) {
    mean[l][0] = 0.05f * l, mean[l][1] = -0.03f * l, mean[l][2] = 0.5f;
    for (float& v : log_scale[l]) v = -3.0f;
    quat[l][0] = 1, quat[l][1] = quat[l][2] = quat[l][3] = 0.1f;
  }
  for (float& v : quat[0]) v = 0.0f;                             // zero quaternion: identity
  quat[1][2] = INFINITY;                                         // infinite component: identity
  quat[2][3] = NAN;                                              // NaN component: culled (NaN rotation)
  for (float& v : quat[3]) v = 1e-30f;                           // denormal-scale quaternion keeps its direction
  mean[4][1] = NAN;                                              // NaN mean: culled
  mean[5][2] = -10.0f;                                           // behind the camera
  log_scale[6][0] = log_scale[6][1] = log_scale[6][2] = 20.0f;   // enormous: radius capped
  log_scale[7][0] = NAN;                                         // NaN scale: culled
  mean[8][0] = 1e6f;                                             // far off screen
  log_scale[9][0] = log_scale[9][1] = log_scale[9][2] = -80.0f;  // vanishing: the eps2d blur remains
  int compared = 0;
  check_block(mean, log_scale, quat, &compared);
  EXPECT_GE(compared, kLanes - 1);

  // The outcomes themselves, independent of the reference.
  const LaneGaussians in = to_lanes(mean, log_scale, quat);
  LaneGeometry geometry;
  geometry_lanes(cam, in, geometry);
  for (int l : {0, 1})
    for (int k = 0; k < 9; ++k) EXPECT_EQ(geometry.rot.R[k][l], k % 4 == 0 ? 1.0f : 0.0f) << "lane " << l;
  LaneProjection got;
  project_lanes(cam, in, geometry.V, got);
  for (int l : {2, 4, 5, 7, 8}) EXPECT_FALSE(got.visible[l]) << "lane " << l;
  for (int l : {0, 1, 3, 6, 9}) EXPECT_TRUE(got.visible[l]) << "lane " << l;
  EXPECT_EQ(got.radius[0][6], kMaxRadius);
  EXPECT_EQ(got.radius[0][9], std::ceil(kExtentSigmas * std::sqrt(0.3f)));
}

// backward_lanes against ceres::Jet derivatives of the templated forward chain in double:
// L = ⟨∂L/∂mean2d, mean2d⟩ + ⟨∂L/∂conic, conic⟩ + ∂L/∂depth · depth over the mean, log-scales
// and raw quaternion of each lane.
TEST_F(Lanes, BackwardMatchesJetDerivatives) {
  using J = ceres::Jet<double, 10>;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> xy(-2.0f, 2.0f), zr(1.0f, 6.0f), ls(-4.0f, 0.5f), qn(-1.0f, 1.0f),
      gr(-1.0f, 1.0f);
  Mat3<J> W;
  for (int i = 0; i < 9; ++i) W(i / 3, i % 3) = J(cam.W[i]);
  int checked = 0;
  for (int block = 0; block < 60; ++block) {
    LaneGaussians g;
    LaneGradientsIn in;
    for (int l = 0; l < kLanes; ++l) {
      g.mean[0][l] = xy(rng), g.mean[1][l] = xy(rng), g.mean[2][l] = zr(rng);
      for (int k = 0; k < 3; ++k) g.scale[k][l] = std::exp(ls(rng));
      for (int k = 0; k < 4; ++k) g.quat[k][l] = qn(rng) * (block % 7 == 0 ? 1e-3f : 1.0f);
      in.d_mean2d[0][l] = gr(rng), in.d_mean2d[1][l] = gr(rng), in.d_depth[l] = gr(rng);
      for (int k = 0; k < 3; ++k) in.d_conic[k][l] = gr(rng);
    }
    LaneGeometry geometry;
    geometry_lanes(cam, g, geometry);
    LaneProjection proj;
    project_lanes(cam, g, geometry.V, proj);
    for (int l = 0; l < kLanes; ++l)
      for (int k = 0; k < 3; ++k) in.conic[k][l] = proj.conic[k][l];
    LaneGradientsOut out;
    backward_lanes(cam, g, geometry.rot, geometry.V, in, out);
    for (int l = 0; l < kLanes; ++l) {
      if (!proj.visible[l]) continue;
      J mean[3], log_scale[3], quat[4];
      for (int k = 0; k < 3; ++k)
        mean[k] = J(g.mean[k][l], k), log_scale[k] = J(std::log(double(g.scale[k][l])), 3 + k);
      for (int k = 0; k < 4; ++k) quat[k] = J(g.quat[k][l], 6 + k);
      const Vec3<J> p = W * Vec3<J>(mean[0], mean[1], mean[2]) + Vec3<J>(J(cam.t[0]), J(cam.t[1]), J(cam.t[2]));
      // Skip Gaussians at project_ewa's clamp edge, where the derivative jumps.
      const double xz = p[0].a / p[2].a, yz = p[1].a / p[2].a;
      if (std::abs(xz - cam.lim_x_pos) < 1e-3 || std::abs(xz + cam.lim_x_neg) < 1e-3 ||
          std::abs(yz - cam.lim_y_pos) < 1e-3 || std::abs(yz + cam.lim_y_neg) < 1e-3)
        continue;
      const Mat3<J> Vj = W * covariance_3d<J>(log_scale, quat) * W.transpose();
      const Projection<J> pj = project_ewa<J>(p, Vj, K, cam.eps2d);
      const Vec3<J> conic = conic_from_cov2d<J>(pj.cov2d);
      J L = J(in.d_depth[l]) * pj.depth;
      for (int k = 0; k < 2; ++k) L += J(in.d_mean2d[k][l]) * pj.mean2d[k];
      for (int k = 0; k < 3; ++k) L += J(in.d_conic[k][l]) * conic[k];
      const double scale = std::max(1.0, L.v.norm());
      float got[10];
      for (int k = 0; k < 3; ++k) got[k] = out.d_mean[k][l], got[3 + k] = out.d_log_scale[k][l];
      for (int k = 0; k < 4; ++k) got[6 + k] = out.d_quat[k][l];
      for (int k = 0; k < 10; ++k)
        EXPECT_NEAR(got[k], L.v[k], 2e-4 * scale) << "block " << block << " lane " << l << " parameter " << k;
      ++checked;
    }
  }
  EXPECT_GT(checked, 300);
}

TEST(CappedCeil, MatchesCeilAndTheCap) {
  for (float v : {0.0f, 1e-30f, 0.5f, 1.0f, 1.0000001f, 2.5f, 3.9999998f, 4194303.5f, 1048575.2f, 1048576.0f, 1e7f,
                  INFINITY, NAN}) {
    const float want = std::min(kMaxRadius, std::ceil(v));
    EXPECT_EQ(capped_ceil(v), want) << v;
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 2.0e6f);
  for (int i = 0; i < 100000; ++i) {
    const float v = u(rng) / float(1 + i % 1000);
    ASSERT_EQ(capped_ceil(v), std::min(kMaxRadius, std::ceil(v))) << v;
  }
}

}  // namespace
}  // namespace desplat::raster
