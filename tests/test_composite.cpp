// DeSplat's decomposed compositing (docs/METHOD.md §4): the composite's hand-written
// gradient against ceres::Jet per pixel, and the whole two-layer pipeline (static and
// distractor kernels → composite → loss + opacity regularizers) against exact
// derivatives through the brute-force double reference renderer.
#include <gtest/gtest.h>

#include <algorithm>

#include "desplat/raster/composite.hpp"
#include "support/jet_gradient.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

template <typename T>
T clamp01(T v) {
  return v < T(0) ? T(0) : (v > T(1) ? T(1) : v);
}

// Per pixel: the gradient of Σ_c w_c·clamp(C_c) with respect to (C_s, A_s, C_d, A_d),
// exercising values inside [0, 1] and beyond it (the clamp gives zero gradient there).
TEST(Composite, PixelGradientMatchesJet) {
  using J = ceres::Jet<double, 8>;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), wide(-0.3f, 1.4f), w(-1.0f, 1.0f);
  int clamped = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const size_t P = 1;
    std::vector<float> cs(3), as{u(rng)}, cd(3), ad{u(rng)}, d_out(3);
    const std::array<float, 3> bg{u(rng), u(rng), u(rng)};
    for (int c = 0; c < 3; ++c) cs[c] = wide(rng), cd[c] = wide(rng), d_out[c] = w(rng);
    std::vector<float> g_cs(3), g_as(P), g_cd(3), g_ad(P), out(3);
    composite_layers({cs, as}, {cd, ad}, bg, out);
    composite_layers_backward({cs, as}, {cd, ad}, bg, d_out, {g_cs, g_as, g_cd, g_ad});
    // Jet: variables 0-2 C_s, 3 A_s, 4-6 C_d, 7 A_d.
    J x[8];
    for (int k = 0; k < 3; ++k) x[k] = J(cs[k], k), x[4 + k] = J(cd[k], 4 + k);
    x[3] = J(as[0], 3), x[7] = J(ad[0], 7);
    J L(0);
    for (int c = 0; c < 3; ++c) {
      const J raw = composite_unclamped(x[c], x[3], x[4 + c], x[7], J(bg[c]));
      clamped += raw.a < 0 || raw.a > 1;
      L += clamp01(raw) * double(d_out[c]);
      EXPECT_NEAR(out[c], clamp01(raw.a), 1e-6);
    }
    const float got[8] = {g_cs[0], g_cs[1], g_cs[2], g_as[0], g_cd[0], g_cd[1], g_cd[2], g_ad[0]};
    for (int k = 0; k < 8; ++k) EXPECT_NEAR(got[k], L.v[k], 1e-6) << "trial " << trial << " variable " << k;
  }
  EXPECT_GT(clamped, 40);  // the clamp branch was exercised
}

TEST(Composite, WithoutDistractorLayerIsStaticOverBackground) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> cs(30), as(10), zeros3(30, 0.0f), zeros(10, 0.0f), a(30), b(30);
  for (float& v : cs) v = u(rng);
  for (float& v : as) v = u(rng);
  const std::array<float, 3> bg{0.2f, 0.5f, 0.9f};
  composite_layers({cs, as}, {}, bg, a);
  composite_layers({cs, as}, {zeros3, zeros}, bg, b);
  EXPECT_EQ(a, b);
  for (size_t p = 0; p < 10; ++p)
    for (int c = 0; c < 3; ++c)
      EXPECT_FLOAT_EQ(a[3 * p + c], std::clamp(cs[3 * p + c] + (1 - as[p]) * bg[c], 0.0f, 1.0f));
}

TEST(Composite, RegularizersValueAndGradient) {
  std::vector<float> as{0.0f, 0.5f, 1.0f, 0.25f}, ad{1.0f, 0.0f, 0.5f, 0.5f}, cs(12, 0.0f), cd(12, 0.0f);
  std::vector<float> g_as(4, 1.0f), g_ad(4, 2.0f);
  const double v = alpha_regularizers({cs, as}, {cd, ad}, 0.1f, 0.3f, g_as, g_ad);
  // mean(1 − A_s) = 2.25/4, mean(A_d) = 2/4.
  EXPECT_NEAR(v, 0.1 * 2.25 / 4 + 0.3 * 2.0 / 4, 1e-7);
  for (float g : g_as) EXPECT_FLOAT_EQ(g, 1.0f - 0.1f / 4);  // added, not overwritten
  for (float g : g_ad) EXPECT_FLOAT_EQ(g, 2.0f + 0.3f / 4);
}

TEST(Composite, RegularizersWithAMaskAverageOverKeptPixelsOnly) {
  std::vector<float> as{0.0f, 0.5f, 1.0f, 0.25f}, ad{1.0f, 0.0f, 0.5f, 0.5f}, cs(12, 0.0f), cd(12, 0.0f);
  const std::vector<float> keep{1, 0, 1, 1};
  std::vector<float> g_as(4, 1.0f), g_ad(4, 2.0f);
  const double v = alpha_regularizers({cs, as}, {cd, ad}, 0.1f, 0.3f, g_as, g_ad, keep);
  // Kept pixels 0, 2, 3: mean(1 − A_s) = (1 + 0 + 0.75)/3, mean(A_d) = (1 + 0.5 + 0.5)/3.
  EXPECT_NEAR(v, 0.1 * 1.75 / 3 + 0.3 * 2.0 / 3, 1e-7);
  EXPECT_EQ(g_as, (std::vector<float>{1.0f - 0.1f / 3, 1.0f, 1.0f - 0.1f / 3, 1.0f - 0.1f / 3}));
  EXPECT_EQ(g_ad, (std::vector<float>{2.0f + 0.3f / 3, 2.0f, 2.0f + 0.3f / 3, 2.0f + 0.3f / 3}));
  const std::vector<float> none(4, 0.0f);  // nothing kept: no value, no gradient
  EXPECT_EQ(alpha_regularizers({cs, as}, {cd, ad}, 0.1f, 0.3f, g_as, g_ad, none), 0.0);
}

TEST(Composite, SizeMismatchIsAnError) {
  std::vector<float> c(12), a(4), a3(3), out(12);
  EXPECT_THROW(composite_layers({c, a}, {c, a3}, std::array<float, 3>{0, 0, 0}, out), std::invalid_argument);
  std::vector<float> short_out(9);
  EXPECT_THROW(composite_layers({c, a}, {}, std::array<float, 3>{0, 0, 0}, short_out), std::invalid_argument);
}

// The whole step's gradient for both Gaussian sets: L = Σ w·clamp(C) + λ_s·mean(1 − A_s)
// + λ_d·mean(A_d), C the composite of the distractor over the static layer over bg.
std::vector<double> two_layer_jet_gradient(const GaussianSet& s, const GaussianSet& d, const Camera& cam,
                                           const RasterSettings& rs, const std::array<float, 3>& bg,
                                           const std::vector<float>& w, float lambda_s, float lambda_d) {
  constexpr int kChunk = 8;
  using J = ceres::Jet<double, kChunk>;
  std::vector<float> flat = flatten_params(s);
  const size_t n_static = flat.size();
  const std::vector<float> flat_d = flatten_params(d);
  flat.insert(flat.end(), flat_d.begin(), flat_d.end());
  std::vector<double> grad(flat.size());
  auto to_jets = [](const GaussianSet& g, const std::vector<J>& values, size_t at) {
    RefGaussians<J> r;
    r.color_mode = g.color_mode;
    r.sh_degree = g.sh_degree;
    for (auto [dst, src] :
         {std::pair{&r.means, &g.means}, std::pair{&r.log_scales, &g.log_scales}, std::pair{&r.quats, &g.quats},
          std::pair{&r.opacity_logits, &g.opacity_logits}, std::pair{&r.colors, &g.colors}}) {
      dst->assign(values.begin() + at, values.begin() + at + src->size());
      at += src->size();
    }
    return r;
  };
  const size_t P = size_t(cam.width) * cam.height;
  for (size_t start = 0; start < flat.size(); start += kChunk) {
    std::vector<J> values(flat.size());
    for (size_t i = 0; i < flat.size(); ++i) values[i] = J(flat[i]);
    for (int k = 0; k < kChunk && start + k < flat.size(); ++k) values[start + k].v[k] = 1.0;
    const RefImage<J> is = reference_render<J>(to_jets(s, values, 0), cam, rs);
    const RefImage<J> id = reference_render<J>(to_jets(d, values, n_static), cam, rs);
    J L(0), sum_s(0), sum_d(0);
    for (size_t p = 0; p < P; ++p) {
      for (int c = 0; c < 3; ++c)
        L +=
            clamp01(composite_unclamped(is.color[3 * p + c], is.alpha[p], id.color[3 * p + c], id.alpha[p], J(bg[c]))) *
            double(w[3 * p + c]);
      sum_s += J(1) - is.alpha[p];
      sum_d += id.alpha[p];
    }
    L += sum_s * (double(lambda_s) / P) + sum_d * (double(lambda_d) / P);
    for (int k = 0; k < kChunk && start + k < flat.size(); ++k) grad[start + k] = L.v[k];
  }
  return grad;
}

TEST(Composite, TwoLayerBackwardMatchesAutodiffThroughReference) {
  for (int seed = 0; seed < 3; ++seed) {
    std::mt19937 rng(300 + seed);
    const Camera cam = random_camera(rng, 22, 17, 20.0f);
    SceneSpec ss;
    ss.count = 8, ss.sh_degree = 1, ss.spread = 1.0f, ss.log_scale_min = -2.0f, ss.sh_sigma = 0.6f;
    const GaussianSet statics = random_gaussians(rng, ss);
    SceneSpec ds = ss;
    ds.count = 6, ds.mode = ColorMode::RGB, ds.logit_max = 4.0f;
    const GaussianSet distractors = random_gaussians(rng, ds);
    const std::array<float, 3> bg{0.3f, 0.8f, 0.1f};
    const float lambda_s = 0.7f, lambda_d = 0.4f;  // large, so their terms are visible in the sum
    std::normal_distribution<float> nrm(0.0f, 1.0f);
    const size_t P = size_t(cam.width) * cam.height;
    std::vector<float> w(3 * P);
    for (float& x : w) x = nrm(rng);
    RasterSettings rs;

    RasterOutput fs, fd;
    rasterize_forward(statics.view(), cam, rs, fs);
    rasterize_forward(distractors.view(), cam, rs, fd);
    std::vector<float> gcs(3 * P), gas(P), gcd(3 * P), gad(P);
    composite_layers_backward({fs.color, fs.alpha}, {fd.color, fd.alpha}, bg, w, {gcs, gas, gcd, gad});
    alpha_regularizers({fs.color, fs.alpha}, {fd.color, fd.alpha}, lambda_s, lambda_d, gas, gad);
    RasterGradients grad_s, grad_d;
    rasterize_backward(statics.view(), cam, rs, fs, gcs, gas, {}, grad_s);
    rasterize_backward(distractors.view(), cam, rs, fd, gcd, gad, {}, grad_d);
    std::vector<float> got = flatten_grads(grad_s);
    const std::vector<float> got_d = flatten_grads(grad_d);
    got.insert(got.end(), got_d.begin(), got_d.end());

    const std::vector<double> want = two_layer_jet_gradient(statics, distractors, cam, rs, bg, w, lambda_s, lambda_d);
    ASSERT_EQ(got.size(), want.size());
    // Same budget as the kernel tests (test_backward.cpp): 2e-4 of the largest exact
    // gradient of the set plus 1e-5; a wrong term in the composite is O(1) off.
    const size_t n_static = flatten_params(statics).size();
    for (auto [lo, hi, name] :
         {std::tuple{size_t(0), n_static, "static"}, std::tuple{n_static, want.size(), "distractor"}}) {
      double scale = 0;
      for (size_t i = lo; i < hi; ++i) scale = std::max(scale, std::abs(want[i]));
      ASSERT_GT(scale, 0) << name;
      for (size_t i = lo; i < hi; ++i) {
        ASSERT_TRUE(std::isfinite(got[i]));
        EXPECT_NEAR(got[i], want[i], 2e-4 * scale + 1e-5) << name << " parameter " << (i - lo) << " seed " << seed;
      }
    }
  }
}

}  // namespace
}  // namespace desplat::test
