// A COLMAP image record for a camera at `center` looking at the world origin, y axis down
// (world up is +y), as the synthetic captures in the tests place their cameras.
#pragma once

#include <Eigen/Geometry>
#include <string>

#include "desplat/io/colmap.hpp"

namespace desplat::testing {

inline colmap::Image look_at_origin(const Eigen::Vector3d& center, uint32_t id, std::string name) {
  const Eigen::Vector3d f = -center.normalized();
  const Eigen::Vector3d r = Eigen::Vector3d(0, 1, 0).cross(f).normalized();
  Eigen::Matrix3d R;
  R.row(0) = r;
  R.row(1) = f.cross(r);
  R.row(2) = f;
  const Eigen::Quaterniond q(R);
  const Eigen::Vector3d t = -R * center;
  colmap::Image im;
  im.id = id;
  im.qvec_wxyz = {q.w(), q.x(), q.y(), q.z()};
  im.tvec = {t.x(), t.y(), t.z()};
  im.camera_id = 1;
  im.name = std::move(name);
  return im;
}

}  // namespace desplat::testing
