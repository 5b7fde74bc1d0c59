// Degenerate and extreme inputs: outputs and gradients stay finite, and agree with the
// brute-force reference (values) and ceres::Jet (gradients) wherever those are finite.
#include <gtest/gtest.h>

#include "support/jet_gradient.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

Camera simple_camera(int w, int h, float f = 30) {
  Camera cam;
  cam.width = w;
  cam.height = h;
  cam.fx = cam.fy = f;
  cam.cx = w * 0.5f;
  cam.cy = h * 0.5f;
  return cam;
}

GaussianSet single(float x, float y, float z, float log_scale, float logit = 1.0f) {
  GaussianSet g;
  g.sh_degree = 1;
  g.resize(1);
  g.means = {x, y, z};
  g.log_scales = {log_scale, log_scale, log_scale};
  g.quats = {0.9f, 0.1f, -0.3f, 0.2f};
  g.opacity_logits = {logit};
  g.colors = {0.3f, -0.2f, 0.1f, 0.05f, 0.1f, -0.1f, 0.2f, 0.0f, 0.1f, -0.05f, 0.02f, 0.1f};
  return g;
}

GaussianSet concat(const GaussianSet& a, const GaussianSet& b) {
  GaussianSet g = a;
  for (auto [dst, src] :
       {std::pair{&g.means, &b.means}, std::pair{&g.log_scales, &b.log_scales}, std::pair{&g.quats, &b.quats},
        std::pair{&g.opacity_logits, &b.opacity_logits}, std::pair{&g.colors, &b.colors}})
    dst->insert(dst->end(), src->begin(), src->end());
  return g;
}

bool all_finite(const std::vector<float>& v) {
  for (float x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

struct Result {
  RasterOutput out;
  RasterGradients grads;
  std::vector<float> wC, wA, wD;
};

// Forward + backward with random loss weights; everything must be finite, and the
// image must match the double reference within the forward test's tolerance.
Result run_and_check(const GaussianSet& g, const Camera& cam, const std::string& label, bool jet = true) {
  Result r;
  RasterSettings s;
  rasterize_forward(g.view(), cam, s, r.out);
  EXPECT_TRUE(all_finite(r.out.color) && all_finite(r.out.alpha) && all_finite(r.out.depth)) << label;
  EXPECT_TRUE(all_finite(r.out.means2d) && all_finite(r.out.conics) && all_finite(r.out.depths)) << label;
  const RefImage<double> ref = reference_render<double>(to_ref<double>(g), cam, s);
  for (size_t i = 0; i < ref.alpha.size(); ++i) {
    EXPECT_EQ(ref.near_threshold[i], 0) << label << ": the case must not sit on a threshold";
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(r.out.color[3 * i + ch], ref.color[3 * i + ch], 2e-5) << label;
    EXPECT_NEAR(r.out.alpha[i], ref.alpha[i], 2e-5) << label;
    EXPECT_NEAR(r.out.depth[i], ref.depth[i], 2e-5 * std::max(1.0, std::abs(ref.depth[i]))) << label;
  }
  std::mt19937 rng(9);
  std::normal_distribution<float> n(0, 1);
  const size_t pixels = size_t(cam.width) * cam.height;
  r.wC.resize(3 * pixels), r.wA.resize(pixels), r.wD.resize(pixels);
  for (auto* v : {&r.wC, &r.wA, &r.wD})
    for (float& x : *v) x = n(rng);
  rasterize_backward(g.view(), cam, s, r.out, r.wC, r.wA, r.wD, r.grads);
  for (const auto* v : {&r.grads.means, &r.grads.log_scales, &r.grads.quats, &r.grads.opacity_logits, &r.grads.colors,
                        &r.grads.means2d, &r.grads.absgrad})
    EXPECT_TRUE(all_finite(*v)) << label;
  if (jet) {
    const std::vector<double> want = jet_gradient(g, cam, s, r.wC, r.wA, r.wD);
    const std::vector<float> got = flatten_grads(r.grads);
    double scale = 0;
    for (double w : want) scale = std::max(scale, std::abs(w));
    for (size_t i = 0; i < want.size(); ++i)
      EXPECT_NEAR(got[i], want[i], 2e-4 * scale + 1e-5) << label << " param " << i;
  }
  return r;
}

double total_alpha(const RasterOutput& o) {
  double s = 0;
  for (float a : o.alpha) s += a;
  return s;
}

TEST(HardCases, BehindTheCameraContributesNothing) {
  const Camera cam = simple_camera(20, 20);
  const GaussianSet in_front = single(0, 0, 3, std::log(0.3f));
  const GaussianSet g = concat(in_front, single(0, 0, -3, std::log(0.3f)));
  const Result r = run_and_check(g, cam, "behind");
  EXPECT_EQ(r.out.visible[1], 0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(r.grads.means[3 + k], 0.0f);
}

TEST(HardCases, NearPlane) {
  const Camera cam = simple_camera(20, 20);
  RasterSettings s;
  // Exactly at the near plane: culled.
  const Result at = run_and_check(single(0, 0, s.near_plane, std::log(0.001f)), cam, "at near");
  EXPECT_EQ(at.out.visible[0], 0);
  EXPECT_EQ(total_alpha(at.out), 0.0);
  // Just past it: rendered, huge on screen, everything finite and matching.
  const Result past = run_and_check(single(0.001f, 0, 0.0105f, std::log(0.001f)), cam, "past near");
  EXPECT_EQ(past.out.visible[0], 1);
  EXPECT_GT(total_alpha(past.out), 0.0);
}

TEST(HardCases, FarOutsideTheFrustum) {
  const Camera cam = simple_camera(20, 20);
  const Result r = run_and_check(single(1e6f, -1e6f, 2, std::log(0.5f)), cam, "outside");
  EXPECT_EQ(r.out.visible[0], 0);
}

TEST(HardCases, TinyAndHugeScales) {
  const Camera cam = simple_camera(24, 20);
  run_and_check(single(0.01f, 0.02f, 2, std::log(1e-6f)), cam, "tiny");
  const Result huge = run_and_check(single(0.01f, 0.02f, 2, std::log(1e3f), -1.0f), cam, "huge");
  EXPECT_GT(total_alpha(huge.out), 0.0);
}

TEST(HardCases, ExtremeAnisotropy) {
  const Camera cam = simple_camera(24, 20);
  GaussianSet g = single(0.05f, 0, 3, 0);
  g.log_scales = {std::log(0.5f), std::log(0.5e-6f), std::log(0.5e-6f)};  // axis ratio 1e6
  const Result r = run_and_check(g, cam, "needle");
  EXPECT_GT(total_alpha(r.out), 0.0);
  g.quats = {1, 0, 0, 0};  // aligned with the image x axis
  run_and_check(g, cam, "aligned needle");
}

TEST(HardCases, ZeroAndDenormalQuaternions) {
  const Camera cam = simple_camera(20, 20);
  GaussianSet g = single(0.1f, 0, 3, 0);
  g.log_scales = {std::log(0.4f), std::log(0.1f), std::log(0.05f)};
  g.quats = {0, 0, 0, 0};
  const Result zero = run_and_check(g, cam, "zero quaternion", /*jet=*/false);
  GaussianSet identity = g;
  identity.quats = {1, 0, 0, 0};
  RasterOutput ref;
  rasterize_forward(identity.view(), cam, RasterSettings{}, ref);
  EXPECT_EQ(zero.out.color, ref.color);  // zero quaternion renders as the identity rotation

  // A denormal quaternion keeps its direction: (0, ε, ε, 0) renders like (0, 1, 1, 0).
  g.quats = {0, 1e-40f, 1e-40f, 0};
  ASSERT_EQ(std::fpclassify(g.quats[1]), FP_SUBNORMAL);
  const Result denormal = run_and_check(g, cam, "denormal quaternion", /*jet=*/false);
  GaussianSet unit = g;
  unit.quats = {0, 1, 1, 0};
  rasterize_forward(unit.view(), cam, RasterSettings{}, ref);
  for (size_t i = 0; i < ref.color.size(); ++i) EXPECT_NEAR(denormal.out.color[i], ref.color[i], 1e-6);
}

TEST(HardCases, SaturatedOpacityLogits) {
  const Camera cam = simple_camera(20, 20);
  const Result opaque = run_and_check(single(0.05f, 0.05f, 3, std::log(0.3f), 30.0f), cam, "logit +30");
  float max_alpha = 0;
  for (float a : opaque.out.alpha) max_alpha = std::max(max_alpha, a);
  EXPECT_FLOAT_EQ(max_alpha, 0.999f);  // the α clamp
  const Result clear = run_and_check(single(0, 0, 3, std::log(0.3f), -30.0f), cam, "logit -30");
  EXPECT_EQ(total_alpha(clear.out), 0.0);
}

TEST(HardCases, TenThousandOpaqueGaussiansOnOnePixel) {
  const Camera cam = simple_camera(3, 2, 5);
  GaussianSet g;
  g.sh_degree = 0;
  g.resize(10000);
  for (int i = 0; i < 10000; ++i) {
    g.means[3 * i + 2] = 1.0f + 1e-3f * i;
    for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(0.5f);
    g.opacity_logits[i] = 8.0f;
    g.colors[3 * i] = 0.3f;
  }
  const Result r = run_and_check(g, cam, "10k stack", /*jet=*/false);
  for (float a : r.out.alpha) EXPECT_GT(a, 0.999f);
  // Transmittance stops at the first Gaussian that would push it below 1e-4; all later
  // Gaussians receive no gradient.
  EXPECT_EQ(r.grads.opacity_logits[5000], 0.0f);
}

TEST(HardCases, ZeroAndOneGaussian) {
  const Camera cam = simple_camera(17, 33);
  GaussianSet empty;
  RasterOutput out;
  rasterize_forward(empty.view(), cam, RasterSettings{}, out);
  EXPECT_EQ(out.color, std::vector<float>(3 * 17 * 33, 0.0f));
  EXPECT_EQ(out.alpha, std::vector<float>(17 * 33, 0.0f));
  RasterGradients grads;
  rasterize_backward(empty.view(), cam, RasterSettings{}, out, {}, {}, {}, grads);
  EXPECT_TRUE(grads.means.empty());
  run_and_check(single(0.2f, -0.1f, 2.5f, std::log(0.2f)), cam, "one Gaussian");
}

TEST(HardCases, OnePixelImage) {
  const Camera cam = simple_camera(1, 1, 2);
  std::mt19937 rng(1);
  SceneSpec spec;
  spec.count = 5;
  spec.spread = 0.3f;
  GaussianSet g = random_gaussians(rng, spec);
  for (int i = 0; i < 5; ++i) g.means[3 * i + 2] += 3;
  const Result r = run_and_check(g, cam, "1x1");
  EXPECT_GT(r.out.alpha[0], 0.0f);
}

}  // namespace
}  // namespace desplat::test
