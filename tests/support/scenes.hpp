// Small random scenes for the kernel tests, deterministic from a seed.
#pragma once

#include <cmath>
#include <random>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"

namespace desplat::test {

// Camera at a random position looking roughly at the origin, from an axis-angle
// rotation, so R_cw and t_cw are both non-trivial.
inline Camera random_camera(std::mt19937& rng, int width, int height, float focal) {
  std::uniform_real_distribution<float> u(-0.3f, 0.3f);
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.fx = focal;
  cam.fy = focal * 1.1f;
  cam.cx = width * 0.5f + u(rng) * 2;
  cam.cy = height * 0.5f + u(rng) * 2;
  const float ax = u(rng), ay = u(rng), az = u(rng);
  const float angle = std::sqrt(ax * ax + ay * ay + az * az);
  const float kx = ax / angle, ky = ay / angle, kz = az / angle;
  const float c = std::cos(angle), s = std::sin(angle), v = 1 - c;
  cam.R_cw = {c + kx * kx * v,      kx * ky * v - kz * s, kx * kz * v + ky * s, ky * kx * v + kz * s, c + ky * ky * v,
              ky * kz * v - kx * s, kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v};
  cam.t_cw = {u(rng), u(rng), 4.0f + u(rng)};
  return cam;
}

struct SceneSpec {
  int count = 20;
  float spread = 1.5f;  // half-width of the cube around the origin
  float log_scale_min = -2.5f, log_scale_max = -0.5f;
  float logit_min = -2.0f, logit_max = 3.0f;
  float sh_sigma = 0.3f;  // std-dev of SH coefficients
  int sh_degree = 3;
  ColorMode mode = ColorMode::SphericalHarmonics;
};

inline GaussianSet random_gaussians(std::mt19937& rng, const SceneSpec& spec) {
  GaussianSet g;
  g.color_mode = spec.mode;
  g.sh_degree = spec.sh_degree;
  g.resize(spec.count);
  std::uniform_real_distribution<float> pos(-spec.spread, spec.spread);
  std::uniform_real_distribution<float> ls(spec.log_scale_min, spec.log_scale_max);
  std::uniform_real_distribution<float> logit(spec.logit_min, spec.logit_max);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  for (int i = 0; i < spec.count; ++i) {
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = pos(rng), g.log_scales[3 * i + k] = ls(rng);
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = normal(rng);
    g.opacity_logits[i] = logit(rng);
  }
  for (float& c : g.colors) c = spec.mode == ColorMode::RGB ? unit(rng) : normal(rng) * spec.sh_sigma;
  return g;
}

}  // namespace desplat::test
