// The interactive 3D view in report.html: the static model's Gaussians drawn by our own small
// WebGL2 splatting viewer (no library fits: none is packaged by Debian, and the page must work
// without a network). Private to the jobs layer.
//
// What it draws: each Gaussian as a screen-space ellipse from its projected covariance (the
// EWA projection of docs/METHOD.md §3 with the same 0.3 px² dilation), view-independent
// colour from the SH DC term, back-to-front alpha blending after a CPU depth sort. It does
// not evaluate higher SH bands, so view-dependent highlights are missing.
#pragma once

#include <array>
#include <optional>
#include <string>

#include "desplat/core/gaussians.hpp"

namespace desplat {

// A starting camera in the PLY's (COLMAP's) frame: x_cam = R·x + t, +z forward, +y down.
struct ViewerCamera {
  std::array<double, 9> R{1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major
  std::array<double, 3> t{0, 0, 0};
  double fx = 500, fy = 500, cx = 320, cy = 240;
  int width = 640, height = 480;
};

// The HTML section: a canvas, the Gaussians as base64 float32 data and the viewer script.
// At most `max_gaussians` are embedded (the most opaque and largest first), so a big model
// still makes a page that can be mailed. `gaussians` in SH mode, as read_gaussian_ply gives.
std::string splat_viewer_section(const GaussianSet& gaussians, const std::optional<ViewerCamera>& start,
                                 const std::array<float, 3>& background, size_t max_gaussians = 300000);

}  // namespace desplat
