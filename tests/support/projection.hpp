// Pinhole projection in double, for tests that check where something lands in a view.
#pragma once

#include <array>
#include <cstddef>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"

namespace desplat::test {

// Where world point x lands in `cam`: (u, v) in pixels and the camera-space depth z.
inline std::array<double, 3> project_point(const Camera& cam, const std::array<float, 3>& x) {
  double pc[3];
  for (int r = 0; r < 3; ++r)
    pc[r] = double(cam.R_cw[3 * r]) * x[0] + double(cam.R_cw[3 * r + 1]) * x[1] + double(cam.R_cw[3 * r + 2]) * x[2] +
            cam.t_cw[r];
  return {cam.fx * pc[0] / pc[2] + cam.cx, cam.fy * pc[1] / pc[2] + cam.cy, pc[2]};
}

// The same for Gaussian i's mean.
inline std::array<double, 3> project_mean(const Camera& cam, const GaussianSet& g, size_t i) {
  return project_point(cam, {g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]});
}

}  // namespace desplat::test
