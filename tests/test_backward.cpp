// Hand-written gradients of the whole kernel against (1) exact derivatives of the
// brute-force reference via ceres::Jet and (2) central finite differences of the
// kernel itself.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "support/jet_gradient.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

struct Loss {
  std::vector<float> wC, wA, wD;  // ∂L/∂color, ∂L/∂alpha, ∂L/∂depth
};

Loss random_loss(std::mt19937& rng, const Camera& cam) {
  std::normal_distribution<float> n(0, 1);
  const size_t pixels = size_t(cam.width) * cam.height;
  Loss l{std::vector<float>(3 * pixels), std::vector<float>(pixels), std::vector<float>(pixels)};
  for (auto* v : {&l.wC, &l.wA, &l.wD})
    for (float& x : *v) x = n(rng);
  return l;
}

// Compares gradients group by group. Float32 accumulates each gradient over every
// pixel the Gaussian touches (hundreds of terms, each from ~100 flops) and the
// backward pass reconstructs transmittance by division; the expected relative error
// is ~1e-5 of the group's largest gradient. 2e-4·max|g| + 1e-5 allows for cancelling
// sums while a wrong term (a missed factor, sign, or branch) shows up as O(1).
void expect_gradients_match(const GaussianSet& g, const RasterGradients& got, const std::vector<double>& want,
                            double rel_tol, const std::string& label) {
  const std::vector<float> flat = flatten_grads(got);
  ASSERT_EQ(flat.size(), want.size());
  size_t at = 0;
  for (const ParamGroupInfo& info : kParamGroupTable) {
    const size_t size = (g.*info.values).size();
    const char* group = info.name;
    // The rasterizer never reads the appearance features (these sets carry none);
    // test_appearance.cpp checks their gradient.
    if (info.id == ParamGroup::Features) {
      EXPECT_EQ(size, 0u);
      continue;
    }
    double scale = 0;
    for (size_t i = at; i < at + size; ++i) scale = std::max(scale, std::abs(want[i]));
    for (size_t i = at; i < at + size; ++i) {
      ASSERT_TRUE(std::isfinite(flat[i])) << label << " " << group;
      EXPECT_NEAR(flat[i], want[i], rel_tol * scale + 1e-5)
          << label << " " << group << " element " << (i - at) << " (group max " << scale << ")";
    }
    EXPECT_GT(scale, 0) << label << " " << group << ": the scene must exercise this gradient";
    at += size;
  }
}

struct Case {
  int width, height, count;
  float focal;
  ColorMode mode;
  int sh_degree, active_degree;
  float logit_max;  // high values exercise the 0.999 α clamp and early termination
};

GaussianSet case_gaussians(const Case& c, std::mt19937& rng) {
  SceneSpec spec;
  spec.count = c.count;
  spec.mode = c.mode;
  spec.sh_degree = c.sh_degree;
  spec.spread = 1.0f;
  spec.log_scale_min = -2.0f;
  spec.logit_max = c.logit_max;
  spec.sh_sigma = 0.5f;  // some colors fall below zero: the clamp is exercised
  return random_gaussians(rng, spec);
}

RasterSettings case_settings(const Case& c, KernelIsa isa) {
  RasterSettings s;
  s.active_sh_degree = c.active_degree;
  s.isa = isa;
  return s;
}

// Every case runs once per pixel-loop path (raster.hpp, KernelIsa); a path this CPU cannot
// run is skipped, and says so.
class BackwardVsJet : public ::testing::TestWithParam<std::tuple<Case, KernelIsa>> {};

TEST_P(BackwardVsJet, MatchesAutodiffReference) {
  const auto [c, isa] = GetParam();
  if (!cpu_supports(isa)) GTEST_SKIP() << kernel_isa_name(isa) << " is not supported by this CPU";
  for (int seed = 0; seed < 3; ++seed) {
    std::mt19937 rng(77 + seed * 13 + c.count);
    const Camera cam = random_camera(rng, c.width, c.height, c.focal);
    const GaussianSet g = case_gaussians(c, rng);
    const RasterSettings s = case_settings(c, isa);
    const Loss loss = random_loss(rng, cam);
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    RasterGradients grads;
    rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, loss.wD, grads);
    const std::vector<double> want = jet_gradient(g, cam, s, loss.wC, loss.wA, loss.wD);
    expect_gradients_match(g, grads, want, 2e-4, "seed " + std::to_string(seed));
  }
}

// Training passes no depth gradient, and the pixel loop then leaves the depth term out
// (tile_kernels.inl, kWithDepth). That path against the Jets with a zero depth weight, and
// bit for bit against the loop given an all-zero depth gradient.
TEST_P(BackwardVsJet, WithoutDepthGradientMatchesAutodiffAndTheZeroDepthGradient) {
  const auto [c, isa] = GetParam();
  if (!cpu_supports(isa)) GTEST_SKIP() << kernel_isa_name(isa) << " is not supported by this CPU";
  std::mt19937 rng(91 + c.count);
  const Camera cam = random_camera(rng, c.width, c.height, c.focal);
  const GaussianSet g = case_gaussians(c, rng);
  const RasterSettings s = case_settings(c, isa);
  const Loss loss = random_loss(rng, cam);
  const std::vector<float> zero_depth(loss.wD.size(), 0.0f);
  RasterOutput out;
  rasterize_forward(g.view(), cam, s, out);
  RasterGradients without, with_zeros;
  rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, {}, without);
  rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, zero_depth, with_zeros);
  const std::vector<double> want = jet_gradient(g, cam, s, loss.wC, loss.wA, zero_depth);
  expect_gradients_match(g, without, want, 2e-4, "no depth gradient");
  const std::vector<float> a = flatten_grads(without), b = flatten_grads(with_zeros);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i)
    ASSERT_EQ(std::bit_cast<uint32_t>(a[i]), std::bit_cast<uint32_t>(b[i])) << "element " << i;
  EXPECT_EQ(without.absgrad, with_zeros.absgrad);
}

INSTANTIATE_TEST_SUITE_P(
    RandomScenes, BackwardVsJet,
    ::testing::Combine(::testing::Values(Case{20, 18, 6, 18, ColorMode::SphericalHarmonics, 3, 3, 2.0f},
                                         Case{33, 17, 8, 25, ColorMode::SphericalHarmonics, 3, 2, 2.0f},
                                         Case{24, 24, 10, 20, ColorMode::SphericalHarmonics, 1, 1, 9.0f},
                                         Case{19, 21, 7, 20, ColorMode::RGB, 0, -1, 4.0f}),
                       ::testing::Values(KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512)),
    [](const auto& info) {
      return "case" + std::to_string(info.index / 3) + "_" + kernel_isa_name(std::get<1>(info.param));
    });

// Only ∂L/∂depth, only ∂L/∂alpha: each output's backward path alone.
TEST(Backward, EachOutputAlone) {
  std::mt19937 rng(5);
  const Camera cam = random_camera(rng, 21, 17, 20);
  SceneSpec spec;
  spec.count = 6;
  spec.spread = 1.0f;
  spec.log_scale_min = -2.0f;
  const GaussianSet g = random_gaussians(rng, spec);
  const Loss loss = random_loss(rng, cam);
  const std::vector<float> zero3(loss.wC.size(), 0.0f), zero1(loss.wA.size(), 0.0f);
  RasterSettings s;
  RasterOutput out;
  rasterize_forward(g.view(), cam, s, out);
  RasterGradients grads;
  rasterize_backward(g.view(), cam, s, out, {}, loss.wA, {}, grads);
  // Alpha does not depend on color: that group is exactly zero; the others match.
  for (float v : grads.colors) EXPECT_EQ(v, 0.0f);
  const std::vector<double> want_a = jet_gradient(g, cam, s, zero3, loss.wA, zero1);
  const std::vector<float> flat = flatten_grads(grads);
  double scale = 0;
  for (double w : want_a) scale = std::max(scale, std::abs(w));
  for (size_t i = 0; i < flat.size(); ++i) EXPECT_NEAR(flat[i], want_a[i], 2e-4 * scale + 1e-5) << i;

  rasterize_backward(g.view(), cam, s, out, {}, {}, loss.wD, grads);
  const std::vector<double> want_d = jet_gradient(g, cam, s, zero3, zero1, loss.wD);
  const std::vector<float> flat_d = flatten_grads(grads);
  scale = 0;
  for (double w : want_d) scale = std::max(scale, std::abs(w));
  for (size_t i = 0; i < flat_d.size(); ++i) EXPECT_NEAR(flat_d[i], want_d[i], 2e-4 * scale + 1e-5) << i;
}

// A scene built to be smooth in every parameter (all α in (1/255, 0.999), transmittance
// far above 1e-4, colors inside the clamp, projections inside the FOV clamp), so
// central differences of the float kernel are meaningful.
TEST(Backward, MatchesCentralFiniteDifferences) {
  Camera cam;
  cam.width = 16;
  cam.height = 12;
  cam.fx = cam.fy = 10;
  cam.cx = 8.2f;
  cam.cy = 5.9f;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  GaussianSet g;
  g.sh_degree = 1;
  g.resize(4);
  for (int i = 0; i < 4; ++i) {
    g.means[3 * i] = 0.3f * u(rng), g.means[3 * i + 1] = 0.2f * u(rng), g.means[3 * i + 2] = 3.0f + 0.5f * i;
    for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(3.0f + 0.5f * u(rng));
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = u(rng);
    g.opacity_logits[i] = -0.5f + 0.5f * u(rng);
  }
  for (float& c : g.colors) c = 0.2f * u(rng);
  const Loss loss = random_loss(rng, cam);
  RasterSettings s;

  auto loss_of = [&](const GaussianSet& gs) {
    RasterOutput o;
    rasterize_forward(gs.view(), cam, s, o);
    double L = 0;
    for (size_t i = 0; i < o.color.size(); ++i) L += double(o.color[i]) * loss.wC[i];
    for (size_t i = 0; i < o.alpha.size(); ++i) L += double(o.alpha[i]) * loss.wA[i] + double(o.depth[i]) * loss.wD[i];
    return L;
  };
  RasterOutput out;
  rasterize_forward(g.view(), cam, s, out);
  for (size_t i = 0; i < out.alpha.size(); ++i) ASSERT_LT(out.alpha[i], 0.999f);  // smooth regime
  RasterGradients grads;
  rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, loss.wD, grads);
  const std::vector<float> analytic = flatten_grads(grads);

  // h = 1e-2 balances truncation error (O(h²)·third derivative, ~1e-4 here) against
  // float32 round-off in L (~1e-6·Σ|w| ≈ 1e-3 over 2h), so ~1% of the largest gradient.
  constexpr float h = 1e-2f;
  std::vector<double> numeric;
  for (const ParamGroupInfo& info : kParamGroupTable) {
    for (size_t i = 0; i < (g.*info.values).size(); ++i) {
      GaussianSet gp = g, gm = g;
      (gp.*info.values)[i] += h;
      (gm.*info.values)[i] -= h;
      numeric.push_back((loss_of(gp) - loss_of(gm)) / (2.0 * h));
    }
  }
  expect_gradients_match(g, grads, numeric, 1e-2, "finite differences");
  // And the autodiff reference agrees with both on this scene.
  expect_gradients_match(g, grads, jet_gradient(g, cam, s, loss.wC, loss.wA, loss.wD), 2e-4, "jet");
  (void)analytic;
}

// The densification statistic by its definition: run the backward pass once per pixel
// with only that pixel's loss weights, and sum the absolute per-pixel ∂L/∂μ2d.
TEST(Backward, AbsGradIsSumOfPerPixelAbsoluteGradients) {
  std::mt19937 rng(3);
  const Camera cam = random_camera(rng, 18, 14, 18);
  SceneSpec spec;
  spec.count = 5;
  spec.spread = 0.8f;
  spec.log_scale_min = -1.8f;
  const GaussianSet g = random_gaussians(rng, spec);
  const Loss loss = random_loss(rng, cam);
  RasterSettings s;
  RasterOutput out;
  rasterize_forward(g.view(), cam, s, out);
  RasterGradients full;
  rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, loss.wD, full);

  const size_t pixels = size_t(cam.width) * cam.height;
  std::vector<double> abs_x(spec.count, 0.0), abs_y(spec.count, 0.0);
  RasterGradients one;
  for (size_t p = 0; p < pixels; ++p) {
    std::vector<float> wC(3 * pixels, 0.0f), wA(pixels, 0.0f), wD(pixels, 0.0f);
    for (int ch = 0; ch < 3; ++ch) wC[3 * p + ch] = loss.wC[3 * p + ch];
    wA[p] = loss.wA[p];
    wD[p] = loss.wD[p];
    rasterize_backward(g.view(), cam, s, out, wC, wA, wD, one);
    for (int i = 0; i < spec.count; ++i) {
      abs_x[i] += std::abs(one.means2d[2 * i]);
      abs_y[i] += std::abs(one.means2d[2 * i + 1]);
    }
  }
  int nonzero = 0;
  for (int i = 0; i < spec.count; ++i) {
    const double want = std::hypot(abs_x[i], abs_y[i]);
    EXPECT_NEAR(full.absgrad[i], want, 1e-4 * want + 1e-6) << "Gaussian " << i;
    EXPECT_GE(full.absgrad[i] * (1 + 1e-5), std::hypot(full.means2d[2 * i], full.means2d[2 * i + 1]));
    nonzero += want > 0;
  }
  EXPECT_GE(nonzero, 3);
}

// The backward skips the entries the forward marked blank (RasterOutput::entry_blank: the
// Gaussian's box reaches the tile, its chord none of the tile's pixel rows). On every
// pixel-loop path, with thin tilted Gaussians whose boxes hold many such tiles:
// - no pixel of a blank entry's tile reaches α = 1/255 for its Gaussian (brute force over the
//   tile, σ in double, a 10⁻³ relative slack for the loops' float rounding);
// - clearing the flags, so that the backward walks those entries too, changes no bit of any
//   gradient.
TEST(Backward, BlankEntriesHoldNothingAndSkippingThemChangesNoBit) {
  for (const KernelIsa isa : {KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512}) {
    if (!cpu_supports(isa)) continue;
    std::mt19937 rng(17);
    const Camera cam = random_camera(rng, 96, 80, 70);
    SceneSpec spec;
    spec.count = 300;
    spec.log_scale_min = -4.0f;
    spec.log_scale_max = -0.5f;
    const GaussianSet g = random_gaussians(rng, spec);
    const Loss loss = random_loss(rng, cam);
    RasterSettings s;
    s.isa = isa;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    ASSERT_EQ(out.entry_blank.size(), out.tile_entries.size());
    const int tiles_x = (cam.width + kTileSize - 1) / kTileSize;
    int blank = 0;
    for (size_t t = 0; t + 1 < out.tile_offsets.size(); ++t)
      for (int e = out.tile_offsets[t]; e < out.tile_offsets[t + 1]; ++e) {
        if (!out.entry_blank[e]) continue;
        ++blank;
        const int i = out.tile_entries[e];
        const double a = out.conics[3 * i], b = out.conics[3 * i + 1], c = out.conics[3 * i + 2];
        const int x0 = int(t % tiles_x) * kTileSize, y0 = int(t / tiles_x) * kTileSize;
        double most = 0;
        for (int y = y0; y < std::min(y0 + kTileSize, cam.height); ++y)
          for (int x = x0; x < std::min(x0 + kTileSize, cam.width); ++x) {
            const double dx = out.means2d[2 * i] - (x + 0.5), dy = out.means2d[2 * i + 1] - (y + 0.5);
            most = std::max(most, out.opacity[i] * std::exp(-(0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy)));
          }
        EXPECT_LT(most, (1.0 + 1e-3) / 255.0) << kernel_isa_name(isa) << " Gaussian " << i << " tile " << t;
      }
    EXPECT_GT(blank, 100) << kernel_isa_name(isa);
    RasterGradients skipped, walked;
    rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, loss.wD, skipped);
    std::fill(out.entry_blank.begin(), out.entry_blank.end(), uint8_t{0});
    rasterize_backward(g.view(), cam, s, out, loss.wC, loss.wA, loss.wD, walked);
    auto same_bits = [](const std::vector<float>& x, const std::vector<float>& y) {
      return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(float)) == 0;
    };
    EXPECT_TRUE(same_bits(skipped.means, walked.means)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.log_scales, walked.log_scales)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.quats, walked.quats)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.opacity_logits, walked.opacity_logits)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.colors, walked.colors)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.means2d, walked.means2d)) << kernel_isa_name(isa);
    EXPECT_TRUE(same_bits(skipped.absgrad, walked.absgrad)) << kernel_isa_name(isa);
  }
}

}  // namespace
}  // namespace desplat::test
