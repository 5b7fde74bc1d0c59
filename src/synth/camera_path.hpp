// Where the synthetic views are: the lens (a COLMAP camera) and one pose per view along an
// orbit or a forward-facing spiral, every camera looking at ViewsSpec::target, or along a walk,
// every camera looking ahead in the direction of walking.
// Frames as synth.hpp: world z up; poses world-to-camera in COLMAP's convention.
#pragma once

#include <Eigen/Core>
#include <glm/gtc/quaternion.hpp>
#include <vector>

#include "desplat/io/colmap.hpp"
#include "desplat/synth/synth.hpp"

namespace desplat::synth {

struct ViewPose {
  Eigen::Matrix3d R_cw;    // world-to-camera rotation: rows are the camera's x (right),
                           // y (down) and z (viewing direction) in world coordinates
  Eigen::Vector3d t_cw;    // world-to-camera translation: p_cam = R_cw·p + t_cw
  Eigen::Vector3d center;  // camera center in world coordinates
  Eigen::Vector3d target;  // the point it looks at (orbit, forward: ViewsSpec::target; walk: the
                           // point ViewsSpec::radius ahead), the distance distractors scale with
};

// PINHOLE (fx, fy, cx, cy) or OPENCV (… k1, k2, p1, p2) with id 1, fx = fy from the field of view.
colmap::Camera make_lens(const CameraSpec& spec);

// The pose looking from `center` at `target` with world z as "up" in the image.
ViewPose look_at(const Eigen::Vector3d& center, const Eigen::Vector3d& target);

// The unit quaternion of a rotation matrix (a proper rotation; GLM is column-major, R[c][r]),
// as images.bin stores R_cw.
glm::dquat quaternion_of(const glm::dmat3& R);

// views.count poses in view order (deterministic in `seed` when position_jitter > 0).
std::vector<ViewPose> camera_path(const ViewsSpec& views, uint64_t seed);

}  // namespace desplat::synth
