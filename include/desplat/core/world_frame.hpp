// The normalized training frame (docs/METHOD.md §1) and the way back to the input frame.
//
// normalized = (original − center) · scale, a translation and a uniform scale with
// no rotation, so quaternions and SH coefficients are the same in both frames and a
// Gaussian's log-scales differ by log(scale). Training runs in the normalized frame;
// everything written for other tools (PLY, cameras) goes back to the original
// (COLMAP) frame.
#pragma once

#include <array>

namespace desplat {

struct WorldNormalization {
  std::array<double, 3> center{0, 0, 0};  // [original units]
  double scale = 1;                       // normalized units per original unit

  std::array<double, 3> to_normalized(const std::array<double, 3>& p) const {
    return {(p[0] - center[0]) * scale, (p[1] - center[1]) * scale, (p[2] - center[2]) * scale};
  }
  std::array<double, 3> to_original(const std::array<double, 3>& p) const {
    return {p[0] / scale + center[0], p[1] / scale + center[1], p[2] / scale + center[2]};
  }
};

}  // namespace desplat
