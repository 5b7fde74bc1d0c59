// Pinhole camera as the rasterizer sees it.
//
// Frames and units (docs/METHOD.md §1, COLMAP convention):
//   * world-to-camera: p_cam = R_cw · p_world + t_cw; the camera looks along +z,
//     x points right and y points down in the image.
//   * intrinsics in pixels: u = fx·x/z + cx, v = fy·y/z + cy. Pixel (i, j) covers
//     [i, i+1) × [j, j+1), so its center is (i + 0.5, j + 0.5).
// Plain value type; copying is cheap.
#pragma once

#include <array>

namespace desplat {

struct Camera {
  float fx = 0, fy = 0;       // focal lengths [px]
  float cx = 0, cy = 0;       // principal point [px]
  int width = 0, height = 0;  // image size [px]
  // World-to-camera rotation, row-major 3×3 (R_cw[3*r + c]).
  std::array<float, 9> R_cw{1, 0, 0, 0, 1, 0, 0, 0, 1};
  // World-to-camera translation [world units].
  std::array<float, 3> t_cw{0, 0, 0};

  // Camera center in world coordinates: −R_cwᵀ · t_cw.
  std::array<float, 3> center() const;

  // The world point at camera-space position p_cam: R_cwᵀ · (p_cam − t_cw) (computed in double).
  std::array<float, 3> to_world(const std::array<double, 3>& p_cam) const;

  // The row-major index of the pixel world point x projects into (computed in double), or
  // −1 when x is not in front of the camera (z ≤ 1e-6) or lands outside the image.
  long long pixel_of(const std::array<float, 3>& x) const;

  // Throws std::invalid_argument naming the problem when the camera is unusable:
  // non-positive or non-finite focal length, non-positive image size, non-finite
  // principal point or pose.
  void validate() const;
};

}  // namespace desplat
