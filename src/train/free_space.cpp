// Free space along the camera path; see include/desplat/train/free_space.hpp.
#include "desplat/train/free_space.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

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
  if (!(settings.radius > 0 || settings.blind_gap > 0) || cameras.size() < 2) return path;
  path.median_depth = median_scene_depth(cameras, points);
  if (!(path.median_depth > 0)) return path;
  path.radius = std::max(0.0, settings.radius * path.median_depth);
  path.by_extent = settings.by_extent;
  path.blind_gap = std::max(0.0f, settings.blind_gap);
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
    path.from_camera.push_back(cameras[i]);
    path.to_camera.push_back(cameras[i + 1]);
  }
  return path;
}

bool in_blind_gap(const std::array<double, 3>& p, const Camera& a, const Camera& b, double gap_fraction) {
  const auto ca = a.center(), cb = b.center();
  const std::array<double, 3> da{ca[0], ca[1], ca[2]}, db{cb[0], cb[1], cb[2]};
  double length2 = 0, ahead = 0;
  for (int k = 0; k < 3; ++k) {
    length2 += (db[k] - da[k]) * (db[k] - da[k]);
    // Row 2 of R_cw is the camera's viewing direction in the world frame.
    ahead += (p[k] - 0.5 * (da[k] + db[k])) * (double(a.R_cw[6 + k]) + double(b.R_cw[6 + k]));
  }
  if (!(ahead > 0) || distance_to_segment(p, da, db) > gap_fraction * std::sqrt(length2)) return false;
  const std::array<float, 3> x{float(p[0]), float(p[1]), float(p[2])};
  return a.pixel_of(x) < 0 && b.pixel_of(x) < 0;
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

double tube_mahalanobis2(const std::array<double, 3>& p, const std::array<double, 3>& a, const std::array<double, 3>& b,
                         const float* log_scale, const float* quat, double r) {
  // In the Gaussian's own frame (columns of R) Σ + r²·I is diagonal: s_k² + r².
  double qn = 0;
  for (int k = 0; k < 4; ++k) qn += double(quat[k]) * quat[k];
  qn = qn > 0 ? std::sqrt(qn) : 1.0;
  const double w = quat[0] / qn, x = quat[1] / qn, y = quat[2] / qn, z = quat[3] / qn;
  const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  double inv_var[3];
  for (int k = 0; k < 3; ++k) inv_var[k] = 1.0 / (std::exp(2.0 * double(log_scale[k])) + r * r);
  // f(t) = |L(a − p + t·(b − a))|² with L = diag(inv_var)^½ Rᵀ: a quadratic in t, minimized on [0, 1].
  double u[3] = {0, 0, 0}, v[3] = {0, 0, 0};  // Rᵀ(a − p), Rᵀ(b − a)
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j) {
      u[k] += R[j][k] * (a[j] - p[j]);
      v[k] += R[j][k] * (b[j] - a[j]);
    }
  double uv = 0, vv = 0;
  for (int k = 0; k < 3; ++k) uv += inv_var[k] * u[k] * v[k], vv += inv_var[k] * v[k] * v[k];
  const double t = vv > 0 ? std::clamp(-uv / vv, 0.0, 1.0) : 0.0;
  double f = 0;
  for (int k = 0; k < 3; ++k) f += inv_var[k] * (u[k] + t * v[k]) * (u[k] + t * v[k]);
  return f;
}

std::vector<uint8_t> on_camera_path(const CameraPath& path, const std::vector<float>& means,
                                    const std::vector<float>& log_scales, const std::vector<float>& quats) {
  const size_t n = means.size() / 3;
  std::vector<uint8_t> out(n, 0);
  if (path.empty()) return out;
  if (path.by_extent && (log_scales.size() != 3 * n || quats.size() != 4 * n))
    throw std::invalid_argument("on_camera_path: judging by extent needs every Gaussian's scales and rotation");
  // Each segment's box, grown per Gaussian by how far its test can reach: the radius, or with
  // by_extent √(r² + s_max²) (Σ + r²·I ≤ (s_max² + r²)·I). Most Gaussians are far from every segment.
  std::vector<std::array<double, 6>> boxes(path.from.size());
  for (size_t s = 0; s < boxes.size(); ++s)
    for (int k = 0; k < 3; ++k) {
      boxes[s][k] = std::min(path.from[s][k], path.to[s][k]);
      boxes[s][3 + k] = std::max(path.from[s][k], path.to[s][k]);
    }
  // The blind-gap rule reaches blind_gap × the segment's length from it.
  std::vector<double> gap_reach(path.from.size(), 0.0);
  const bool gaps =
      path.blind_gap > 0 && path.from_camera.size() == path.from.size() && path.to_camera.size() == path.from.size();
  if (gaps)
    for (size_t s = 0; s < gap_reach.size(); ++s) {
      double length2 = 0;
      for (int k = 0; k < 3; ++k) length2 += (path.to[s][k] - path.from[s][k]) * (path.to[s][k] - path.from[s][k]);
      gap_reach[s] = path.blind_gap * std::sqrt(length2);
    }
#pragma omp parallel for schedule(static)
  for (long long i = 0; i < (long long)n; ++i) {
    const std::array<double, 3> p{means[3 * i], means[3 * i + 1], means[3 * i + 2]};
    double reach = path.radius;
    if (path.by_extent) {
      const double s_max =
          std::exp(double(std::max({log_scales[3 * i], log_scales[3 * i + 1], log_scales[3 * i + 2]})));
      reach = std::sqrt(path.radius * path.radius + s_max * s_max);
    }
    uint8_t verdict = kOffPath;
    for (size_t s = 0; s < boxes.size() && verdict != kInTube; ++s) {
      const auto& box = boxes[s];
      const double r = std::max(reach, gap_reach[s]);
      if (p[0] < box[0] - r || p[1] < box[1] - r || p[2] < box[2] - r || p[0] > box[3] + r || p[1] > box[4] + r ||
          p[2] > box[5] + r)
        continue;
      const bool in_tube =
          path.radius > 0 && (path.by_extent ? tube_mahalanobis2(p, path.from[s], path.to[s], &log_scales[3 * i],
                                                                 &quats[4 * i], path.radius) <= 1.0
                                             : distance_to_segment(p, path.from[s], path.to[s]) <= path.radius);
      if (in_tube)
        verdict = kInTube;
      else if (gaps && verdict == kOffPath && in_blind_gap(p, path.from_camera[s], path.to_camera[s], path.blind_gap))
        verdict = kInBlindGap;
    }
    out[size_t(i)] = verdict;
  }
  return out;
}

}  // namespace desplat
