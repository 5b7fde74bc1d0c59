// Free space along the camera path (docs/METHOD.md §7, camera path). A photographer walks the
// camera from one photo to the next, so the space between two consecutive photos' camera
// centres held nothing solid. A static Gaussian there is a floater: no training view sees it
// from near (it is behind or beside them, or too close to count in their loss), yet a test
// view taken on the same path looks straight into it. Two rules: a tube about the path, and
// the blind gap in front of each step that neither of its two photos sees.
//
// Units: positions in the normalized world frame (docs/METHOD.md §1); the radius and the
// longest segment are fractions of the median scene depth, the blind gap a fraction of each
// step's length, so the rules do not depend on the scene's scale.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "desplat/core/camera.hpp"

namespace desplat {

struct CameraPathSettings {
  // Cull static Gaussians whose centre lies within this × the median scene depth of the path.
  // 0 turns the rule off (--preset paper). The tube is wider than the path itself because the
  // floaters that spoil a test view also lie beside it, where the photo between two training
  // photos passes close to them (docs/METHOD.md §7).
  float radius = 0.08f;
  // Consecutive photos farther apart than this × the median scene depth are not a path the
  // camera was walked along (an unordered collection, a gap in the capture): no segment.
  float max_segment = 0.5f;
  // Judge a Gaussian by its extent, not its centre alone: it is on the path when the path comes
  // within one standard deviation of it in the metric of Σ + r²·I (its covariance with the
  // tube's radius r added in every direction). A point-sized Gaussian is the centre rule; a
  // large one whose centre lies just outside the tube but which sprawls across it (a sky
  // floater painting clouds for far views) is on the path too (docs/METHOD.md §7). Off by
  // default: it helped one sky scene of four and cost a little on the other three.
  bool by_extent = false;
  // Cull static Gaussians in the blind gap between two consecutive photos: within this × the
  // step between them of the segment joining their centres, in front of the pair, and in
  // neither photo. No photo taken near such a Gaussian constrains it; only far views do, which
  // see it against the sky or background, so they paint sky there (a ring of inward-looking
  // cameras under a sky). A view taken between the two photos looks into it from under half a
  // step. 0 turns the rule off (--preset paper). 0.5 finds such Gaussians in sky scenes and
  // none in sky-free ones; a wider gap (1.0) starts taking Gaussians of sky-free scenes too
  // (docs/METHOD.md §7).
  float blind_gap = 0.5f;
};

// The segments between consecutive training cameras that the rules keep, and their sizes.
struct CameraPath {
  std::vector<std::array<double, 3>> from, to;  // segment endpoints (camera centres) [world]
  double radius = 0;                            // [world units]; 0: no tube rule
  bool by_extent = false;                       // CameraPathSettings::by_extent
  double median_depth = 0;                      // [world units]; 0: no points in front of any camera
  std::size_t skipped_segments = 0;             // consecutive pairs farther apart than max_segment
  double blind_gap = 0;                         // CameraPathSettings::blind_gap; 0: no blind-gap rule
  std::vector<Camera> from_camera, to_camera;   // the segments' endpoint cameras (for blind_gap)
  bool empty() const { return from.empty() || (radius <= 0 && blind_gap <= 0); }
};

// Per camera, the median depth (camera-space z) of the points in front of it (z > 0); then the
// median of those over the cameras that have any. 0 when no camera has a point in front.
double median_scene_depth(const std::vector<Camera>& cameras, const std::vector<std::array<float, 3>>& points);

// The path through `cameras` in the order given (training views sorted by name: the capture
// order of a phone or camera). Without points, or with settings.radius and blind_gap both 0,
// the path is empty.
CameraPath camera_path(const std::vector<Camera>& cameras, const std::vector<std::array<float, 3>>& points,
                       const CameraPathSettings& settings);

// Distance from p to the segment [a, b] (b == a: to the point).
double distance_to_segment(const std::array<double, 3>& p, const std::array<double, 3>& a,
                           const std::array<double, 3>& b);

// min over x in [a, b] of (x − p)ᵀ (Σ + r²·I)⁻¹ (x − p), with Σ = R·diag(exp(2·log_scale))·Rᵀ
// and R the rotation of `quat` (w, x, y, z; normalized here). With scales → 0 it is
// distance_to_segment(p, a, b)² / r².
double tube_mahalanobis2(const std::array<double, 3>& p, const std::array<double, 3>& a, const std::array<double, 3>& b,
                         const float* log_scale, const float* quat, double r);

// Whether world point p lies in the blind gap of the segment from camera a to camera b: within
// gap_fraction × |b − a| of the segment, in front of it ((p − midpoint) · (a's + b's viewing
// direction) > 0), and in neither camera's image (Camera::pixel_of is −1 for both).
bool in_blind_gap(const std::array<double, 3>& p, const Camera& a, const Camera& b, double gap_fraction);

// What on_camera_path found for a Gaussian.
enum PathVerdict : uint8_t { kOffPath = 0, kInTube = 1, kInBlindGap = 2 };

// Per Gaussian of `means` [N·3, world], its PathVerdict: kInTube when its centre lies within
// path.radius of a segment, or with path.by_extent (then `log_scales` [N·3] and `quats` [N·4]
// are needed) tube_mahalanobis2 ≤ 1 for a segment; else kInBlindGap when in_blind_gap holds
// for a segment (path.blind_gap > 0); else kOffPath.
std::vector<uint8_t> on_camera_path(const CameraPath& path, const std::vector<float>& means,
                                    const std::vector<float>& log_scales = {}, const std::vector<float>& quats = {});

}  // namespace desplat
