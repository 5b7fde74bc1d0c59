// The tiled forward kernel against the brute-force double-precision reference.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "desplat/raster/raster.hpp"
#include "support/reference_render.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

struct ImageError {
  double color = 0, alpha = 0, depth = 0;
  size_t ambiguous = 0;  // pixels skipped because a decision sits on its threshold
};

ImageError compare(const RasterOutput& out, const RefImage<double>& ref) {
  ImageError e;
  for (size_t i = 0; i < ref.alpha.size(); ++i) {
    if (ref.near_threshold[i]) {
      ++e.ambiguous;
      continue;
    }
    for (int ch = 0; ch < 3; ++ch) e.color = std::max(e.color, std::abs(out.color[3 * i + ch] - ref.color[3 * i + ch]));
    e.alpha = std::max(e.alpha, std::abs(out.alpha[i] - ref.alpha[i]));
    e.depth = std::max(e.depth, std::abs(out.depth[i] - ref.depth[i]) / std::max(1.0, std::abs(ref.depth[i])));
  }
  return e;
}

// Float32 kernel vs double reference. Each output is a sum of at most a few hundred
// blended terms, each a product of ~5 rounded factors, and the transmittance is a
// running product; with unit round-off 6e-8 the expected error is ~1e-6 and the
// worst case over thousands of pixels a few times that. 2e-5 (absolute for color and
// alpha in [0, 1], relative for depth) leaves that margin and still catches any real
// semantic difference (a skipped or extra Gaussian changes a pixel by ≥ 1/255·T).
constexpr double kTolerance = 2e-5;

struct Case {
  int width, height, count;
  float focal;
  ColorMode mode;
  int sh_degree, active_degree;
};

// Every case runs once per pixel-loop path (raster.hpp, KernelIsa); a path this CPU cannot
// run is skipped, and says so.
class ForwardVsReference : public ::testing::TestWithParam<std::tuple<Case, KernelIsa>> {};

TEST_P(ForwardVsReference, MatchesBruteForce) {
  const auto [c, isa] = GetParam();
  if (!cpu_supports(isa)) GTEST_SKIP() << kernel_isa_name(isa) << " is not supported by this CPU";
  for (int seed = 0; seed < 5; ++seed) {
    std::mt19937 rng(1000 * c.count + seed);
    const Camera cam = random_camera(rng, c.width, c.height, c.focal);
    SceneSpec spec;
    spec.count = c.count;
    spec.mode = c.mode;
    spec.sh_degree = c.sh_degree;
    const GaussianSet g = random_gaussians(rng, spec);
    RasterSettings s;
    s.active_sh_degree = c.active_degree;
    s.isa = isa;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    EXPECT_EQ(out.isa, isa);
    const RefImage<double> ref = reference_render<double>(to_ref<double>(g), cam, s);
    const ImageError e = compare(out, ref);
    EXPECT_LT(e.color, kTolerance) << "seed " << seed;
    EXPECT_LT(e.alpha, kTolerance) << "seed " << seed;
    EXPECT_LT(e.depth, kTolerance) << "seed " << seed;
    EXPECT_LE(e.ambiguous, ref.alpha.size() / 200) << "seed " << seed;
    // The scene must actually exercise the blending.
    double coverage = 0;
    for (float a : out.alpha) coverage += a;
    EXPECT_GT(coverage / out.alpha.size(), 0.05) << "seed " << seed;
  }
}

INSTANTIATE_TEST_SUITE_P(
    RandomScenes, ForwardVsReference,
    ::testing::Combine(::testing::Values(Case{64, 48, 60, 60, ColorMode::SphericalHarmonics, 3, 3},
                                         Case{37, 23, 40, 30, ColorMode::SphericalHarmonics, 3, 1},
                                         Case{50, 70, 300, 50, ColorMode::SphericalHarmonics, 2, 2},
                                         Case{33, 17, 80, 25, ColorMode::RGB, 0, -1},
                                         Case{96, 64, 500, 80, ColorMode::SphericalHarmonics, 0, 0}),
                       ::testing::Values(KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512)),
    [](const auto& info) {
      return "case" + std::to_string(info.index / 3) + "_" + kernel_isa_name(std::get<1>(info.param));
    });

TEST(Forward, PerGaussianOutputsDescribeTheProjection) {
  std::mt19937 rng(7);
  const Camera cam = random_camera(rng, 48, 32, 40);
  SceneSpec spec;
  spec.count = 50;
  const GaussianSet g = random_gaussians(rng, spec);
  RasterOutput out;
  rasterize_forward(g.view(), cam, RasterSettings{}, out);
  int visible = 0;
  for (int i = 0; i < spec.count; ++i) {
    if (!out.visible[i]) {
      EXPECT_EQ(out.radii[2 * i], 0);
      continue;
    }
    ++visible;
    // Mean: u = fx·x/z + cx from the camera-space point, computed here in double.
    double p[3];
    for (int r = 0; r < 3; ++r) {
      p[r] = cam.t_cw[r];
      for (int k = 0; k < 3; ++k) p[r] += double(cam.R_cw[3 * r + k]) * g.means[3 * i + k];
    }
    EXPECT_NEAR(out.depths[i], p[2], 1e-5 * p[2]);
    EXPECT_NEAR(out.means2d[2 * i], cam.fx * p[0] / p[2] + cam.cx, 1e-4);
    EXPECT_NEAR(out.means2d[2 * i + 1], cam.fy * p[1] / p[2] + cam.cy, 1e-4);
    // Conic is positive definite and radii cover 3.33σ of its inverse.
    const double a = out.conics[3 * i], b = out.conics[3 * i + 1], c = out.conics[3 * i + 2];
    const double det = a * c - b * b;
    ASSERT_GT(det, 0);
    EXPECT_GE(out.radii[2 * i], 3.33 * std::sqrt(c / det) - 1e-3);
    EXPECT_LT(out.radii[2 * i], 3.33 * std::sqrt(c / det) + 1.0 + 1e-3);
    EXPECT_GE(out.radii[2 * i + 1], 3.33 * std::sqrt(a / det) - 1e-3);
  }
  EXPECT_GT(visible, 10);
}

// Binning sorts and counts chunks of Gaussians on the threads and merges them; whatever the
// number of chunks, each tile must list its Gaussians in strictly increasing (depth, id)
// order, each entry's gradient record must lie in its own Gaussian's run (one record per
// entry), and the lists and the render must be the same bits as with one thread.
TEST(Forward, BinningIsOneDepthOrderForAnyThreadCount) {
  std::mt19937 rng(11);
  const Camera cam = random_camera(rng, 128, 96, 90);
  SceneSpec spec;
  spec.count = 2000;
  const GaussianSet g = random_gaussians(rng, spec);
  RasterSettings one;
  one.num_threads = 1;
  RasterOutput ref;
  rasterize_forward(g.view(), cam, one, ref);
  ASSERT_GT(ref.tile_entries.size(), 2000u);
  for (size_t t = 0; t + 1 < ref.tile_offsets.size(); ++t)
    for (int e = ref.tile_offsets[t] + 1; e < ref.tile_offsets[t + 1]; ++e) {
      const int32_t a = ref.tile_entries[e - 1], b = ref.tile_entries[e];
      EXPECT_TRUE(ref.depths[a] < ref.depths[b] || (ref.depths[a] == ref.depths[b] && a < b)) << "tile " << t;
    }
  std::vector<int> owner(ref.record_of_entry.size(), -1);
  for (size_t e = 0; e < ref.record_of_entry.size(); ++e) {
    const int32_t rec = ref.record_of_entry[e];
    ASSERT_TRUE(rec >= 0 && size_t(rec) < owner.size());
    EXPECT_EQ(owner[rec], -1) << "record " << rec << " written twice";
    owner[rec] = ref.tile_entries[e];
  }
  for (size_t i = 0; i + 1 < ref.gaussian_offsets.size(); ++i)
    for (int rec = ref.gaussian_offsets[i]; rec < ref.gaussian_offsets[i + 1]; ++rec)
      EXPECT_EQ(owner[rec], int(i)) << "record " << rec;
  for (int threads : {2, 3, 5}) {
    RasterSettings s;
    s.num_threads = threads;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    EXPECT_EQ(out.tile_offsets, ref.tile_offsets) << threads << " threads";
    EXPECT_EQ(out.tile_entries, ref.tile_entries) << threads << " threads";
    EXPECT_EQ(out.record_of_entry, ref.record_of_entry) << threads << " threads";
    EXPECT_EQ(out.color, ref.color) << threads << " threads";
  }
}

// Gaussians at exactly equal depths (identity rotation, every other mean on one of three
// planes z = const, so their depths are the same float) must still be listed in id order
// within each tile: the depth sort has to keep ties in id order, whatever the thread count.
// The planes sit at random depths, so their float bits differ in every digit the sort uses.
TEST(Forward, EqualDepthsAreListedInIdOrder) {
  std::mt19937 rng(5);
  Camera cam;
  cam.width = 96, cam.height = 64;
  cam.fx = cam.fy = 80.0f, cam.cx = 48.0f, cam.cy = 32.0f;
  cam.t_cw = {0.0f, 0.0f, 4.0f};
  SceneSpec spec;
  spec.count = 1500;
  spec.spread = 1.0f;
  GaussianSet g = random_gaussians(rng, spec);
  std::uniform_real_distribution<float> plane_z(-1.0f, 1.0f);
  const float planes[3] = {plane_z(rng), plane_z(rng), plane_z(rng)};
  for (size_t i = 0; i < g.size(); i += 2) g.means[3 * i + 2] = planes[(i / 2) % 3];
  for (int threads : {1, 2, 3}) {
    RasterSettings s;
    s.num_threads = threads;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    size_t ties = 0;
    for (size_t t = 0; t + 1 < out.tile_offsets.size(); ++t)
      for (int e = out.tile_offsets[t] + 1; e < out.tile_offsets[t + 1]; ++e) {
        const int32_t a = out.tile_entries[e - 1], b = out.tile_entries[e];
        ASSERT_TRUE(out.depths[a] < out.depths[b] || (out.depths[a] == out.depths[b] && a < b))
            << "tile " << t << ", " << threads << " threads";
        ties += out.depths[a] == out.depths[b];
      }
    EXPECT_GT(ties, 300u) << "the scene must list many equal depths next to each other";
  }
}

// The tiles and rows a Gaussian is blended in come from its opacity (blend_radii): every
// pixel where o·e^−σ reaches 1/255, computed here in double from the conic, must lie
// inside that box, and the box never exceeds the 3.33σ one. Opacities span 10⁻³…1, so some
// Gaussians can reach α = 1/255 nowhere (zero box) and the rest have boxes from ~0 to 3.33σ.
TEST(Forward, OpacityExtentCoversEveryPixelWhereAlphaReachesTheCutoff) {
  std::mt19937 rng(11);
  const Camera cam = random_camera(rng, 64, 48, 50);
  SceneSpec spec;
  spec.count = 400;
  GaussianSet g = random_gaussians(rng, spec);
  std::uniform_real_distribution<float> log_o(std::log(1e-3f), 0.0f);
  for (float& logit : g.opacity_logits) {
    const float o = std::min(std::exp(log_o(rng)), 0.9999f);
    logit = std::log(o / (1 - o));
  }
  RasterOutput out;
  rasterize_forward(g.view(), cam, RasterSettings{}, out);
  int checked = 0, never = 0, narrower = 0;
  for (int i = 0; i < spec.count; ++i) {
    if (!out.visible[i]) continue;
    EXPECT_LE(out.blend_radii[2 * i], out.radii[2 * i]);
    EXPECT_LE(out.blend_radii[2 * i + 1], out.radii[2 * i + 1]);
    const double o = out.opacity[i];
    if (o < 0.98 / 255) {  // clearly below the cutoff (the kernel keeps a 1 % margin)
      EXPECT_EQ(out.blend_radii[2 * i], 0) << "Gaussian " << i << " can never reach the cutoff";
      ++never;
      continue;
    }
    narrower += out.blend_radii[2 * i] < out.radii[2 * i];
    const double a = out.conics[3 * i], b = out.conics[3 * i + 1], c = out.conics[3 * i + 2];
    const double mx = out.means2d[2 * i], my = out.means2d[2 * i + 1];
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const double dx = mx - (x + 0.5), dy = my - (y + 0.5);
        const double sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        if (o * std::exp(-sigma) < 1.0 / 255) continue;
        ++checked;
        EXPECT_LE(std::abs(dx), out.blend_radii[2 * i]) << "Gaussian " << i << " pixel " << x << "," << y;
        EXPECT_LE(std::abs(dy), out.blend_radii[2 * i + 1]) << "Gaussian " << i << " pixel " << x << "," << y;
      }
  }
  EXPECT_GT(checked, 1000);
  EXPECT_GT(never, 5);
  EXPECT_GT(narrower, 50);
}

// blend_weights against two independent answers: the closed form for one unoccluded Gaussian,
// and the backward pass's colour gradient (∂ΣC_red/∂c_red,i = Σ_p αᵢTᵢ), which is itself
// checked against Jet derivatives in test_backward.cpp.
TEST(BlendWeights, OneGaussianMatchesTheClosedFormIntegral) {
  // Identity pose, a round Gaussian 1 unit in front: σ = f·s px on screen, plus the 0.3 px²
  // blur. Its α ≥ 1/255 inside q ≤ 2·ln(255·o), so Σ_p α ≈ ∫ o·e^(−q/2) over that disc =
  // 2π·√det Σ2d · (o − 1/255).
  Camera cam;
  cam.width = cam.height = 96;
  cam.fx = cam.fy = 100;
  cam.cx = cam.cy = 48;
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(1);
  g.means = {0, 0, 1};
  const double scale = 0.06;  // 6 px
  for (int k = 0; k < 3; ++k) g.log_scales[k] = float(std::log(scale));
  g.quats = {1, 0, 0, 0};
  const double o = 0.6;
  g.opacity_logits[0] = float(std::log(o / (1 - o)));
  g.colors = {0.5f, 0.5f, 0.5f};
  RasterOutput out;
  rasterize_forward(g.view(), cam, RasterSettings{}, out);
  const double var = (100 * scale) * (100 * scale) + 0.3;
  const double expected = 2 * M_PI * var * (o - 1.0 / 255);
  const std::vector<double> w = blend_weights(out);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NEAR(w[0], expected, 1e-3 * expected);
}

TEST(BlendWeights, EqualTheBackwardColourGradientAndSumToTheAlphaImage) {
  for (int seed = 0; seed < 4; ++seed) {
    std::mt19937 rng(77 + seed);
    const Camera cam = random_camera(rng, 53, 41, 50);
    SceneSpec spec;
    spec.count = 150;
    spec.mode = ColorMode::RGB;
    spec.sh_degree = 0;
    const GaussianSet g = random_gaussians(rng, spec);
    RasterSettings s;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    const std::vector<double> w = blend_weights(out);
    ASSERT_EQ(w.size(), g.size());
    std::vector<float> d_color(3 * size_t(cam.width) * cam.height, 0.0f);
    for (size_t p = 0; p < d_color.size(); p += 3) d_color[p] = 1.0f;  // L = Σ_p C_red(p)
    RasterGradients grads;
    rasterize_backward(g.view(), cam, s, out, d_color, {}, {}, grads);
    double total = 0, alpha_sum = 0;
    int weighted = 0;
    for (size_t i = 0; i < g.size(); ++i) {
      EXPECT_NEAR(w[i], grads.colors[3 * i], 1e-4 * std::max(1.0, w[i])) << "seed " << seed << " Gaussian " << i;
      if (!out.visible[i]) {
        EXPECT_EQ(w[i], 0.0);
      }
      total += w[i];
      weighted += w[i] > 1;
    }
    for (float a : out.alpha) alpha_sum += a;
    EXPECT_NEAR(total, alpha_sum, 1e-5 * alpha_sum) << "seed " << seed;
    EXPECT_GT(weighted, 20) << "seed " << seed;  // the scene exercises the blending
  }
}

}  // namespace
}  // namespace desplat::test
