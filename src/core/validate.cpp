// Input checks for the rasterizer's public types: one clear exception per problem.
#include <cmath>
#include <stdexcept>
#include <string>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"

namespace desplat {

std::array<float, 3> Camera::center() const {
  const auto& R = R_cw;
  return {-(R[0] * t_cw[0] + R[3] * t_cw[1] + R[6] * t_cw[2]), -(R[1] * t_cw[0] + R[4] * t_cw[1] + R[7] * t_cw[2]),
          -(R[2] * t_cw[0] + R[5] * t_cw[1] + R[8] * t_cw[2])};
}

std::array<float, 3> Camera::to_world(const std::array<double, 3>& p_cam) const {
  std::array<float, 3> w{};
  for (int k = 0; k < 3; ++k) {
    double v = 0;
    for (int r = 0; r < 3; ++r) v += double(R_cw[3 * r + k]) * (p_cam[r] - double(t_cw[r]));
    w[k] = float(v);
  }
  return w;
}

long long Camera::pixel_of(const std::array<float, 3>& x) const {
  double p[3];
  for (int r = 0; r < 3; ++r)
    p[r] = double(R_cw[3 * r]) * x[0] + double(R_cw[3 * r + 1]) * x[1] + double(R_cw[3 * r + 2]) * x[2] + t_cw[r];
  if (!(p[2] > 1e-6)) return -1;
  const double u = fx * p[0] / p[2] + cx, v = fy * p[1] / p[2] + cy;
  if (!(u >= 0 && v >= 0 && u < width && v < height)) return -1;
  return (long long)(v)*width + (long long)(u);
}

void Camera::validate() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("camera: " + what); };
  if (!(fx > 0) || !(fy > 0) || !std::isfinite(fx) || !std::isfinite(fy))
    fail("focal length must be positive and finite (fx=" + std::to_string(fx) + ", fy=" + std::to_string(fy) + ")");
  if (width <= 0 || height <= 0)
    fail("image size must be positive (" + std::to_string(width) + "x" + std::to_string(height) + ")");
  if (!std::isfinite(cx) || !std::isfinite(cy)) fail("principal point is not finite");
  for (float v : R_cw)
    if (!std::isfinite(v)) fail("rotation is not finite");
  for (float v : t_cw)
    if (!std::isfinite(v)) fail("translation is not finite");
}

void GaussianView::validate() const {
  const size_t n = size();
  auto expect = [n](size_t got, size_t per, const char* name) {
    if (got != n * per)
      throw std::invalid_argument(std::string("gaussians: ") + name + " has " + std::to_string(got) +
                                  " values, expected " + std::to_string(n * per) + " for " + std::to_string(n) +
                                  " Gaussians");
  };
  if (color_mode == ColorMode::SphericalHarmonics && (sh_degree < 0 || sh_degree > 3))
    throw std::invalid_argument("gaussians: SH degree " + std::to_string(sh_degree) + " is not supported (0..3)");
  expect(means.size(), 3, "means");
  expect(log_scales.size(), 3, "log_scales");
  expect(quats.size(), 4, "quats");
  expect(colors.size(), color_floats_per_gaussian(), "colors");
}

void GaussianSet::resize(size_t n) {
  const size_t old = size();
  means.resize(3 * n, 0.0f);
  log_scales.resize(3 * n, 0.0f);
  quats.resize(4 * n, 0.0f);
  for (size_t i = old; i < n; ++i) quats[4 * i] = 1.0f;
  opacity_logits.resize(n, 0.0f);
  colors.resize(view().color_floats_per_gaussian() * n, 0.0f);
  features.resize(size_t(feature_dim) * n, 0.0f);
}

}  // namespace desplat
