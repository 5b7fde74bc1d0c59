// Free space along the camera path; see include/desplat/train/free_space.hpp.
#include "desplat/train/free_space.hpp"

#include <algorithm>
#include <cmath>

#include "desplat/core/statistics.hpp"

namespace desplat {

double median_scene_depth(const std::vector<Camera>& cameras, const std::vector<std::array<float, 3>>& points) {
  std::vector<double> per_camera;
  std::vector<double> depths;
  for (const Camera& c : cameras) {
    depths.clear();
    for (const auto& x : points) {
      double z = c.t_cw[2];
      for (int k = 0; k < 3; ++k) z += double(c.R_cw[6 + k]) * x[k];
      if (z > 0) depths.push_back(z);
    }
    if (!depths.empty()) per_camera.push_back(median(depths));
  }
  return per_camera.empty() ? 0.0 : median(per_camera);
}

CameraPath camera_path(const std::vector<Camera>& cameras, const std::vector<std::array<float, 3>>& points,
                       const CameraPathSettings& settings) {
  CameraPath path;
  if (!(settings.radius > 0) || cameras.size() < 2) return path;
  path.median_depth = median_scene_depth(cameras, points);
  if (!(path.median_depth > 0)) return path;
  path.radius = settings.radius * path.median_depth;
  const double longest = settings.max_segment * path.median_depth;
  for (size_t i = 0; i + 1 < cameras.size(); ++i) {
    const auto a = cameras[i].center(), b = cameras[i + 1].center();
    const std::array<double, 3> da{a[0], a[1], a[2]}, db{b[0], b[1], b[2]};
    const double step = std::sqrt((db[0] - da[0]) * (db[0] - da[0]) + (db[1] - da[1]) * (db[1] - da[1]) +
                                  (db[2] - da[2]) * (db[2] - da[2]));
    if (step > longest) {
      ++path.skipped_segments;
      continue;
    }
    path.from.push_back(da);
    path.to.push_back(db);
  }
  return path;
}

double distance_to_segment(const std::array<double, 3>& p, const std::array<double, 3>& a,
                           const std::array<double, 3>& b) {
  double d[3], ap[3], len2 = 0, along = 0;
  for (int k = 0; k < 3; ++k) {
    d[k] = b[k] - a[k];
    ap[k] = p[k] - a[k];
    len2 += d[k] * d[k];
    along += ap[k] * d[k];
  }
  const double s = len2 > 0 ? std::clamp(along / len2, 0.0, 1.0) : 0.0;
  double dist2 = 0;
  for (int k = 0; k < 3; ++k) dist2 += (ap[k] - s * d[k]) * (ap[k] - s * d[k]);
  return std::sqrt(dist2);
}

std::vector<uint8_t> on_camera_path(const CameraPath& path, const std::vector<float>& means) {
  const size_t n = means.size() / 3;
  std::vector<uint8_t> out(n, 0);
  if (path.empty()) return out;
  // Each segment's box grown by the radius: most Gaussians are far from every segment.
  std::vector<std::array<double, 6>> boxes(path.from.size());
  for (size_t s = 0; s < boxes.size(); ++s)
    for (int k = 0; k < 3; ++k) {
      boxes[s][k] = std::min(path.from[s][k], path.to[s][k]) - path.radius;
      boxes[s][3 + k] = std::max(path.from[s][k], path.to[s][k]) + path.radius;
    }
#pragma omp parallel for schedule(static)
  for (long long i = 0; i < (long long)n; ++i) {
    const std::array<double, 3> p{means[3 * i], means[3 * i + 1], means[3 * i + 2]};
    for (size_t s = 0; s < boxes.size(); ++s) {
      const auto& box = boxes[s];
      if (p[0] < box[0] || p[1] < box[1] || p[2] < box[2] || p[0] > box[3] || p[1] > box[4] || p[2] > box[5]) continue;
      if (distance_to_segment(p, path.from[s], path.to[s]) <= path.radius) {
        out[size_t(i)] = 1;
        break;
      }
    }
  }
  return out;
}

}  // namespace desplat
