// Lens and camera poses of the synthetic views.
#include "synth/camera_path.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "synth/random.hpp"

namespace desplat::synth {

using Eigen::Vector3d;

colmap::Camera make_lens(const CameraSpec& spec) {
  colmap::Camera cam;
  cam.id = 1;
  cam.width = static_cast<uint64_t>(spec.width);
  cam.height = static_cast<uint64_t>(spec.height);
  const double f = 0.5 * spec.width / std::tan(spec.fov_x_deg * std::numbers::pi / 360);
  const double cx = 0.5 * spec.width + spec.principal_offset_px[0];
  const double cy = 0.5 * spec.height + spec.principal_offset_px[1];
  cam.params = {f, f, cx, cy};
  if (spec.model == "OPENCV") {
    cam.model = colmap::CameraModelId::OpenCV;
    cam.params.insert(cam.params.end(), spec.distortion.begin(), spec.distortion.end());
  } else {
    cam.model = colmap::CameraModelId::Pinhole;
  }
  return cam;
}

// In Eigen rather than GLM: with the build's FMA contraction Eigen's normalized() adds x² + y²
// unfused (one SIMD packet) and fuses z² into the sum, and its matrix-vector product groups its
// terms as its SIMD packets do, which GLM's scalar code compiles differently, so the poses written
// to images.bin would change in their last bits (docs/ARCHITECTURE.md, "Which library owns
// what"); tests/test_pose_math.cpp checks the result against glm::lookAt.
ViewPose look_at(const Vector3d& center, const Vector3d& target) {
  const Vector3d forward = (target - center).normalized();
  // Looking straight up or down: any horizontal "right" will do.
  const Vector3d up = std::abs(forward.z()) > 0.999 ? Vector3d::UnitY() : Vector3d::UnitZ();
  const Vector3d right = forward.cross(up).normalized();
  const Vector3d down = forward.cross(right);
  ViewPose pose;
  pose.R_cw.row(0) = right.transpose();
  pose.R_cw.row(1) = down.transpose();
  pose.R_cw.row(2) = forward.transpose();
  pose.center = center;
  pose.target = target;
  pose.t_cw = -pose.R_cw * center;
  return pose;
}

// Shoemake's method as Eigen's Quaternion(Matrix3) evaluates it, so images.bin keeps the bits of
// the scenes already generated: the w branch whenever the trace R00 + (R11 + R22) is positive
// (glm::quat_cast instead takes the branch of the largest component and sums the trace left to
// right).
glm::dquat quaternion_of(const glm::dmat3& R) {
  const auto m = [&R](int row, int col) { return R[col][row]; };
  const double trace = m(0, 0) + (m(1, 1) + m(2, 2));
  if (trace > 0) {
    const double s = std::sqrt(trace + 1);
    const double f = 0.5 / s;
    return {0.5 * s, (m(2, 1) - m(1, 2)) * f, (m(0, 2) - m(2, 0)) * f, (m(1, 0) - m(0, 1)) * f};
  }
  // From the largest diagonal entry i (the first of equal ones) and the two axes after it.
  int i = 0;
  if (m(1, 1) > m(0, 0)) i = 1;
  if (m(2, 2) > m(i, i)) i = 2;
  const int j = (i + 1) % 3, k = (j + 1) % 3;
  const double s = std::sqrt(m(i, i) - m(j, j) - m(k, k) + 1);
  const double f = 0.5 / s;
  glm::dvec3 xyz;
  xyz[i] = 0.5 * s;
  xyz[j] = (m(j, i) + m(i, j)) * f;
  xyz[k] = (m(k, i) + m(i, k)) * f;
  return {(m(k, j) - m(j, k)) * f, xyz.x, xyz.y, xyz.z};
}

namespace {

// View k of a walk: a straight line `radius` long through the point `height` above the target,
// heading along azimuth start_deg, with a sideways sway (spread[0], three periods over the walk)
// and a vertical bob (spread[1], a period of four frames: a photo every half stride) as a
// hand-held camera has; the camera looks straight ahead, so consecutive views move along their
// viewing direction.
ViewPose walk_pose(const ViewsSpec& v, int k, uint64_t seed) {
  const double deg = std::numbers::pi / 180;
  const Vector3d heading(std::cos(v.start_deg * deg), std::sin(v.start_deg * deg), 0);
  const Vector3d left(-heading.y(), heading.x(), 0);
  const double s = v.count > 1 ? static_cast<double>(k) / (v.count - 1) : 0;
  Vector3d c = Vector3d(v.target[0], v.target[1], v.target[2] + v.height) + (s - 0.5) * v.radius * heading +
               v.spread[0] * std::sin(6 * std::numbers::pi * s) * left +
               v.spread[1] * std::sin(0.5 * std::numbers::pi * k) * Vector3d::UnitZ();
  if (v.position_jitter > 0) {
    Rng rng(seed, Stream::Camera, static_cast<uint64_t>(k));
    for (int a = 0; a < 3; ++a) c[a] += rng.uniform(-v.position_jitter, v.position_jitter);
  }
  return look_at(c, c + v.radius * heading);
}

}  // namespace

std::vector<ViewPose> camera_path(const ViewsSpec& v, uint64_t seed) {
  const Vector3d target(v.target[0], v.target[1], v.target[2]);
  const double deg = std::numbers::pi / 180;
  const int n = v.count;
  std::vector<ViewPose> poses;
  // The forward path's frame: its centre, and the directions across the view at that centre.
  const Vector3d heading(std::cos(v.start_deg * deg), std::sin(v.start_deg * deg), 0);
  const Vector3d path_centre = target + v.radius * heading + Vector3d(0, 0, v.height);
  const ViewPose centre_pose = look_at(path_centre, target);
  for (int k = 0; k < n; ++k) {
    Vector3d c;
    if (v.path == "walk") {
      poses.push_back(walk_pose(v, k, seed));
      continue;
    }
    if (v.path == "orbit") {
      // A closed circle does not repeat its first camera; an open arc ends on its last.
      const double step = v.arc_deg >= 360 ? v.arc_deg / n : v.arc_deg / std::max(1, n - 1);
      const double a = (v.start_deg + step * k) * deg;
      c = target + Vector3d(v.radius * std::cos(a), v.radius * std::sin(a), v.height);
    } else {
      // Two turns of a widening spiral across the view (as LLFF captures), no position repeated.
      const double s = n > 1 ? static_cast<double>(k) / (n - 1) : 0;
      const double theta = 4 * std::numbers::pi * s;
      const double r = 0.4 + 0.6 * s;
      c = path_centre + r * v.spread[0] * std::cos(theta) * centre_pose.R_cw.row(0).transpose() -
          r * v.spread[1] * std::sin(theta) * centre_pose.R_cw.row(1).transpose();
    }
    if (v.position_jitter > 0) {
      Rng rng(seed, Stream::Camera, static_cast<uint64_t>(k));
      for (int a = 0; a < 3; ++a) c[a] += rng.uniform(-v.position_jitter, v.position_jitter);
    }
    poses.push_back(look_at(c, target));
  }
  return poses;
}

}  // namespace desplat::synth
