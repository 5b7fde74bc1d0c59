// Bad input to the rasterizer API throws one clear std::invalid_argument.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "desplat/raster/raster.hpp"

namespace desplat {
namespace {

using ::testing::HasSubstr;

Camera good_camera() {
  Camera c;
  c.width = 8;
  c.height = 6;
  c.fx = c.fy = 10;
  c.cx = 4;
  c.cy = 3;
  return c;
}

GaussianSet good_gaussians() {
  GaussianSet g;
  g.sh_degree = 2;
  g.resize(3);
  for (int i = 0; i < 3; ++i) g.means[3 * i + 2] = 2;
  return g;
}

template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(no exception)";
}

std::string forward_error(const GaussianView& g, const Camera& c, RasterSettings s = {}) {
  RasterOutput out;
  return error_of([&] { rasterize_forward(g, c, s, out); });
}

TEST(ApiErrors, MismatchedArraySizes) {
  GaussianSet g = good_gaussians();
  g.means.pop_back();
  EXPECT_THAT(forward_error(g.view(), good_camera()), HasSubstr("means has 8 values, expected 9"));
  g = good_gaussians();
  g.quats.resize(3);
  EXPECT_THAT(forward_error(g.view(), good_camera()), HasSubstr("quats"));
  g = good_gaussians();
  g.colors.resize(3 * 3 * 4);  // degree-1 sized colors while sh_degree is 2
  EXPECT_THAT(forward_error(g.view(), good_camera()), HasSubstr("colors"));
}

TEST(ApiErrors, BadCamera) {
  const GaussianSet g = good_gaussians();
  Camera c = good_camera();
  c.fx = 0;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("focal length"));
  c = good_camera();
  c.fy = -3;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("focal length"));
  c = good_camera();
  c.fx = NAN;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("focal length"));
  c = good_camera();
  c.width = 0;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("image size"));
  c = good_camera();
  c.height = -4;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("image size"));
  c = good_camera();
  c.t_cw[1] = INFINITY;
  EXPECT_THAT(forward_error(g.view(), c), HasSubstr("translation"));
}

TEST(ApiErrors, ShDegree) {
  GaussianSet g = good_gaussians();
  g.sh_degree = 4;
  g.colors.resize(3 * 3 * 25);
  EXPECT_THAT(forward_error(g.view(), good_camera()), HasSubstr("SH degree 4"));
  g = good_gaussians();
  RasterSettings s;
  s.active_sh_degree = 3;
  EXPECT_THAT(forward_error(g.view(), good_camera(), s), HasSubstr("exceeds the stored SH degree"));
}

TEST(ApiErrors, BackwardInputs) {
  const GaussianSet g = good_gaussians();
  const Camera c = good_camera();
  RasterOutput out;
  rasterize_forward(g.view(), c, RasterSettings{}, out);
  RasterGradients grads;
  std::vector<float> wrong(7);
  EXPECT_THAT(error_of([&] { rasterize_backward(g.view(), c, {}, out, wrong, {}, {}, grads); }),
              HasSubstr("dL_dcolor has 7 values, expected 144"));
  Camera other = c;
  other.width = 9;
  EXPECT_THAT(error_of([&] { rasterize_backward(g.view(), other, {}, out, {}, {}, {}, grads); }),
              HasSubstr("does not match"));
}

}  // namespace
}  // namespace desplat
