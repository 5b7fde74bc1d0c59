// Each hand-written stage VJP against ceres::Jet derivatives of the templated forward
// function, evaluated at the same float inputs in double precision.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <random>

#include "raster/fast_exp.hpp"
#include "raster/stage_math.hpp"
#include "raster/tiles.hpp"

namespace desplat::raster {
namespace {

template <int N>
using Jet = ceres::Jet<double, N>;

// Float VJPs of single stages involve ≤ ~50 flops on O(1) values, so their error is
// a few float ulps of the largest term: 1e-5 relative to the gradient's magnitude.
void expect_close(double got, double want, double scale, const char* what, int i) {
  EXPECT_NEAR(got, want, 1e-5 * std::max(1.0, scale)) << what << " [" << i << "]";
}

// The bound is the one measured over every float in [−87, 0] (fast_exp.hpp): 1.64e-7, 2.01
// ulps at x = −5.19861. A sample of 2 million points stays under it.
TEST(FastExp, RelativeErrorBelow1_7e7AndTwoUlps) {
  double worst = 0, worst_ulps = 0;
  for (int i = 0; i <= 2000000; ++i) {
    const float x = -87.0f * float(i) / 2000000.0f;
    const double exact = std::exp(double(x));
    const double error = std::abs(fast_exp_nonpositive(x) - exact);
    const float rounded = float(exact);
    worst = std::max(worst, error / exact);
    worst_ulps = std::max(worst_ulps, error / double(std::nextafter(rounded, INFINITY) - rounded));
  }
  EXPECT_LT(worst, 1.7e-7);
  EXPECT_LE(worst_ulps, 2.02);
  EXPECT_NEAR(fast_exp_nonpositive(-5.19861f), std::exp(-5.19861), 1.7e-7 * std::exp(-5.19861));
  EXPECT_EQ(fast_exp_nonpositive(0.0f), 1.0f);
  EXPECT_EQ(fast_exp_nonpositive(-100.0f), 0.0f);
  EXPECT_EQ(fast_exp_nonpositive(-INFINITY), 0.0f);
}

TEST(StageVjp, QuaternionToRotation) {
  std::mt19937 rng(1);
  std::normal_distribution<float> n(0, 1);
  for (int trial = 0; trial < 50; ++trial) {
    float q[4], G[9];
    for (float& v : q) v = n(rng) * (trial % 5 == 0 ? 1e-3f : 1.0f);
    for (float& v : G) v = n(rng);
    Jet<4> qj[4];
    for (int i = 0; i < 4; ++i) qj[i] = Jet<4>(q[i], i);
    const Mat3<Jet<4>> R = rotation_from_unit_quat<Jet<4>>(normalize_quat<Jet<4>>(qj));
    Jet<4> L(0);
    Mat3<float> Gm;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) L += R(r, c) * double(G[3 * r + c]), Gm(r, c) = G[3 * r + c];
    const Vec4<float> dq = quat_vjp(q, Gm);
    for (int i = 0; i < 4; ++i) expect_close(dq[i], L.v[i], L.v.norm(), "dq", i);
  }
}

TEST(StageVjp, Covariance3d) {
  std::mt19937 rng(2);
  std::normal_distribution<float> n(0, 1);
  for (int trial = 0; trial < 50; ++trial) {
    float s[3], q[4], G[9];
    for (float& v : s) v = n(rng) - 1.0f;
    for (float& v : q) v = n(rng);
    for (float& v : G) v = n(rng);
    Jet<7> sj[3], qj[4];
    for (int i = 0; i < 3; ++i) sj[i] = Jet<7>(s[i], i);
    for (int i = 0; i < 4; ++i) qj[i] = Jet<7>(q[i], 3 + i);
    const Mat3<Jet<7>> Sigma = covariance_3d<Jet<7>>(sj, qj);
    Jet<7> L(0);
    Mat3<float> Gm;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) L += Sigma(r, c) * double(G[3 * r + c]), Gm(r, c) = G[3 * r + c];
    float ds[3] = {0, 0, 0}, dq[4] = {0, 0, 0, 0};
    covariance_3d_vjp(s, q, Gm, ds, dq);
    for (int i = 0; i < 3; ++i) expect_close(ds[i], L.v[i], L.v.norm(), "ds", i);
    for (int i = 0; i < 4; ++i) expect_close(dq[i], L.v[3 + i], L.v.norm(), "dq", i);
  }
}

// Projection with the field-of-view clamp both inactive and active.
TEST(StageVjp, EwaProjectionAndConic) {
  std::mt19937 rng(3);
  std::normal_distribution<float> n(0, 1);
  const PinholeIntrinsics K{50.f, 55.f, 31.f, 22.f, 64, 48};
  for (int trial = 0; trial < 60; ++trial) {
    const float spread = trial % 3 == 0 ? 4.0f : 0.4f;  // every third one off-screen: clamp active
    const Vec3<float> p(n(rng) * spread, n(rng) * spread, 2.0f + std::abs(n(rng)));
    Eigen::Matrix3f A = Eigen::Matrix3f::Random() * 0.3f;
    const Mat3<float> V = A * A.transpose() + 0.01f * Mat3<float>::Identity();
    const Vec2<float> dm(n(rng), n(rng));
    const Vec3<float> dconic(n(rng), n(rng), n(rng));
    const float ddepth = n(rng);
    // Jet over p (3) and the 6 independent entries of V.
    using J = Jet<9>;
    Vec3<J> pj(J(p[0], 0), J(p[1], 1), J(p[2], 2));
    Mat3<J> Vj;
    int k = 3;
    for (int r = 0; r < 3; ++r)
      for (int c = r; c < 3; ++c) {
        Vj(r, c) = J(V(r, c), k++);
        Vj(c, r) = Vj(r, c);
      }
    const Projection<J> proj = project_ewa<J>(pj, Vj, K, 0.3f);
    const Vec3<J> conic = conic_from_cov2d<J>(proj.cov2d);
    const J L = proj.mean2d[0] * double(dm[0]) + proj.mean2d[1] * double(dm[1]) + conic[0] * double(dconic[0]) +
                conic[1] * double(dconic[1]) + conic[2] * double(dconic[2]) + proj.depth * double(ddepth);

    const Projection<float> pf = project_ewa<float>(p, V, K, 0.3f);
    const Vec3<float> conic_f = conic_from_cov2d<float>(pf.cov2d);
    Vec3<float> d_p;
    Mat3<float> d_V;
    project_ewa_vjp(p, V, K, dm, conic_vjp(conic_f, dconic), ddepth, d_p, d_V);
    const double scale = L.v.norm();
    for (int i = 0; i < 3; ++i) expect_close(d_p[i], L.v[i], scale, "d_p", i);
    k = 3;
    for (int r = 0; r < 3; ++r)
      for (int c = r; c < 3; ++c, ++k) {
        const double got = r == c ? d_V(r, c) : d_V(r, c) + d_V(c, r);  // symmetric entry
        expect_close(got, L.v[k], scale, "d_V", k);
      }
  }
}

TEST(StageVjp, ShColorAllDegrees) {
  std::mt19937 rng(4);
  std::normal_distribution<float> n(0, 1);
  for (int degree = 0; degree <= 3; ++degree)
    for (int trial = 0; trial < 20; ++trial) {
      const int K = (degree + 1) * (degree + 1);
      std::vector<float> coeffs(3 * K);
      for (float& c : coeffs) c = n(rng) * 0.5f;
      const Vec3<float> mean(n(rng), n(rng), n(rng)), center(n(rng), n(rng), n(rng));
      const Vec3<float> dc(n(rng), n(rng), n(rng));
      using J = Jet<51>;  // 48 coefficients + 3 mean coordinates
      std::vector<J> cj(3 * K);
      for (int i = 0; i < 3 * K; ++i) cj[i] = J(coeffs[i], i);
      const Vec3<J> mj(J(mean[0], 48), J(mean[1], 49), J(mean[2], 50));
      const Vec3<J> cen{J(center[0]), J(center[1]), J(center[2])};
      const Vec3<J> color = evaluate_color<J>(true, degree, cj.data(), mj, cen);
      const J L = color[0] * double(dc[0]) + color[1] * double(dc[1]) + color[2] * double(dc[2]);
      std::vector<float> dcoeffs(3 * K, 0.0f);
      Vec3<float> dmean = Vec3<float>::Zero();
      evaluate_color_sh_vjp(degree, coeffs.data(), mean, center, dc, dcoeffs.data(), dmean);
      const double scale = L.v.norm();
      for (int i = 0; i < 3 * K; ++i) expect_close(dcoeffs[i], L.v[i], scale, "dcoeff", i);
      for (int i = 0; i < 3; ++i) expect_close(dmean[i], L.v[48 + i], scale, "dmean", i);
    }
}

// RowChords (tiles.hpp) against the pixel loops' own test, pixel by pixel. Random ellipses
// from round to needle-thin (standard deviations √0.3 … 400 px, the forward's dilation is the
// floor), any tilt, centres in and around a 64×64 image, opacity 2·10⁻³ … 1; boxes as the
// forward builds them (blend_radii). In every tile row of every box:
// - each 8-column half holding a pixel that the loops would blend (their float σ, fast exp
//   and clamp: σ ≥ 0 and α ≥ 1/255) is kept — skipping it would change the render;
// - a half whose pixel centres all lie clearly outside the ellipse (exact σ in double above
//   ln(255·o) plus RowChords' stated margins plus 0.05) is dropped, so the chord does cut.
TEST(RowChords, KeepEveryHalfThePixelLoopsBlendAndDropTheEmptyOnes) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr int kImage = 64;
  int64_t blended_halves = 0, empty_halves = 0, dropped_empty = 0, kept_blended = 0, needles = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    const double s1 = std::exp(std::log(std::sqrt(0.3)) + u(rng) * std::log(400.0 / std::sqrt(0.3)));
    const double s2 = trial % 3 == 0 ? std::sqrt(0.3) + 0.2 * u(rng)
                                     : std::exp(std::log(std::sqrt(0.3)) + u(rng) * std::log(400.0 / std::sqrt(0.3)));
    const double th = 3.14159265358979 * u(rng), co = std::cos(th), si = std::sin(th);
    const double cxx = co * co * s1 * s1 + si * si * s2 * s2, cyy = si * si * s1 * s1 + co * co * s2 * s2;
    const double cxy = co * si * (s1 * s1 - s2 * s2), det = cxx * cyy - cxy * cxy;
    const float a = float(cyy / det), b = float(-cxy / det), c = float(cxx / det);
    const float o = float(std::min(0.9999, std::exp(std::log(2e-3) * u(rng))));
    const float mx = float(-40.0 + (kImage + 80.0) * u(rng)), my = float(-40.0 + (kImage + 80.0) * u(rng));
    const float k = opacity_extent_sigmas(o);
    if (k == 0.0f) continue;
    const int rx =
        int(std::min(std::ceil(kExtentSigmas * std::sqrt(float(cxx))), std::ceil(k * std::sqrt(float(cxx)))));
    const int ry =
        int(std::min(std::ceil(kExtentSigmas * std::sqrt(float(cyy))), std::ceil(k * std::sqrt(float(cyy)))));
    needles += std::max(s1, s2) > 30 * std::min(s1, s2);
    const double level = std::log(255.0 * double(o));
    const double px = rx + 1.0, py = ry + 1.0;
    const double margin = 0.01 + 2e-6 * (0.5 * a * px * px + std::abs(double(b)) * px * py + 0.5 * c * py * py);
    for (int y0 = 0; y0 < kImage; y0 += kTileSize)
      for (int x0 = 0; x0 < kImage; x0 += kTileSize) {
        int r0, r1, h0, h1;
        box_rows_in_tile(my, ry, y0, kTileSize, r0, r1);
        box_halves_in_tile(mx, rx, x0, kTileSize, h0, h1);
        if (h0 > h1 || r0 > r1) continue;
        float shape[kChordFloats];
        chord_shape(a, b, c, o, rx, ry, shape);
        const RowChords chords(shape, mx, x0, h0, h1);
        int32_t row_h0[kTileSize], row_h1[kTileSize];
        chords.row_halves(my, y0, row_h0, row_h1);
        for (int r = r0; r <= r1; ++r) {
          const float dy = my - (y0 + r + 0.5f);
          const int rh0 = row_h0[r], rh1 = row_h1[r];
          for (int h = h0; h <= h1; ++h) {
            bool blended = false, clearly_outside = true;
            for (int col = h * kHalfTile; col < (h + 1) * kHalfTile; ++col) {
              const float dx = mx - (x0 + col + 0.5f);
              const float sigma = gaussian_sigma(a, b, c, dx, dy);
              const float alpha = clamp_alpha(o * fast_exp_nonpositive(-sigma));
              blended |= sigma >= 0.0f && alpha >= kAlphaMin;
              const double ddx = double(mx) - (x0 + col + 0.5), ddy = double(my) - (y0 + r + 0.5);
              const double exact = 0.5 * a * ddx * ddx + double(b) * ddx * ddy + 0.5 * c * ddy * ddy;
              clearly_outside &= exact > level + margin + 0.05;
            }
            const bool kept = rh0 <= h && h <= rh1;
            if (blended) {
              ++blended_halves;
              kept_blended += kept;
              EXPECT_TRUE(kept) << "trial " << trial << " tile " << x0 << "," << y0 << " row " << r << " half " << h;
            }
            if (clearly_outside) ++empty_halves, dropped_empty += !kept;
          }
        }
      }
  }
  EXPECT_EQ(kept_blended, blended_halves);
  EXPECT_GT(blended_halves, 20000);
  EXPECT_GT(needles, 300);
  EXPECT_GT(empty_halves, 5000);
  EXPECT_GE(double(dropped_empty), 0.99 * double(empty_halves)) << dropped_empty << " of " << empty_halves;
}

// A conic that is not positive definite (a ≤ 0, or NaN) gives no chord: the box's halves pass through.
TEST(RowChords, PassTheBoxThroughWhenTheConicIsNotPositiveDefinite) {
  for (const float a : {0.0f, -1.0f, NAN}) {
    float shape[kChordFloats];
    chord_shape(a, 0.0f, 1.0f, 0.5f, 20, 20, shape);
    const RowChords chords(shape, 8.0f, 0, 0, 1);
    int32_t rh0[kTileSize], rh1[kTileSize];
    std::fill(rh0, rh0 + kTileSize, -5);
    std::fill(rh1, rh1 + kTileSize, -5);
    chords.row_halves(8.0f, 0, rh0, rh1);
    for (int r = 0; r < kTileSize; ++r) {
      EXPECT_EQ(rh0[r], 0) << "row " << r;
      EXPECT_EQ(rh1[r], 1) << "row " << r;
    }
  }
}

}  // namespace
}  // namespace desplat::raster
