// points3D and the points2D of every image: surface points sampled through random pixels.
#include "synth/sparse_points.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "desplat/core/statistics.hpp"
#include "desplat/io/camera_models.hpp"
#include "synth/random.hpp"

namespace desplat::synth {
namespace {

struct Sighting {
  int view;
  Vec2 xy;       // exact projection [px]
  double depth;  // camera z [world units]
};

// Where view `v` sees surface point `p` of primitive `primitive`, if it does.
std::optional<Sighting> sight(const SparseInput& in, int v, const Vec3& p, int primitive) {
  const ViewPose& pose = (*in.poses)[static_cast<size_t>(v)];
  const Vec3 q = pose.R_cw * p + pose.t_cw;
  if (q.z() <= 1e-6) return std::nullopt;
  const Vec2 uv{q.x() / q.z(), q.y() / q.z()};
  const Vec2 xy = image_from_camera(in.lens, uv);
  if (!(xy[0] >= 0 && xy[1] >= 0 && xy[0] < static_cast<double>(in.lens.width) &&
        xy[1] < static_cast<double>(in.lens.height)))
    return std::nullopt;
  // A distorted lens can fold far-off points into the image; the pixel's own ray must lead back.
  const Vec2 back = camera_from_image(in.lens, xy);
  if (std::abs(back[0] - uv[0]) + std::abs(back[1] - uv[1]) > 1e-6) return std::nullopt;
  const double distance = (p - pose.center).norm();
  const Ray ray{pose.center, (p - pose.center) / distance};
  const Hit hit = in.statics->nearest(ray);
  const bool reaches = hit.primitive == primitive && std::abs(hit.t - distance) <= 1e-7 * std::max(1.0, distance);
  if (!reaches || std::abs(hit.normal.dot(ray.dir)) < 0.1) return std::nullopt;  // hidden or grazing
  const Primitives& clutter = (*in.distractors)[static_cast<size_t>(v)];
  if (!clutter.empty() && clutter.nearest(ray, distance).hit()) return std::nullopt;
  return Sighting{v, xy, q.z()};
}

Vec2 project(const SparseInput& in, int v, const Vec3& p) {
  const ViewPose& pose = (*in.poses)[static_cast<size_t>(v)];
  const Vec3 q = pose.R_cw * p + pose.t_cw;
  return image_from_camera(in.lens, {q.x() / q.z(), q.y() / q.z()});
}

uint8_t to_byte(double c) { return static_cast<uint8_t>(std::lround(std::clamp(c, 0.0, 1.0) * 255)); }

}  // namespace

void add_sparse_points(const SparseInput& in, colmap::Model& model) {
  const int views = static_cast<int>(in.poses->size());
  const auto w = static_cast<double>(in.lens.width), h = static_cast<double>(in.lens.height);
  const double focal = pinhole_intrinsics(in.lens).fx;
  const int64_t attempts = 20 * static_cast<int64_t>(in.spec.count);
  uint64_t next_id = 1;
  for (int64_t a = 0; a < attempts && next_id <= static_cast<uint64_t>(in.spec.count); ++a) {
    Rng rng(in.seed, Stream::Points, static_cast<uint64_t>(a));  // one stream per attempt
    const int from = rng.integer(0, views - 1);
    const ViewPose& pose = (*in.poses)[static_cast<size_t>(from)];
    const Vec2 uv = camera_from_image(in.lens, {rng.uniform(0, w), rng.uniform(0, h)});
    const Ray ray{pose.center, (pose.R_cw.transpose() * Vec3(uv[0], uv[1], 1)).normalized()};
    const Hit hit = in.statics->nearest(ray);
    if (!hit.hit()) continue;
    const Vec3 surface = ray.origin + hit.t * ray.dir;

    std::vector<Sighting> seen;
    for (int v = 0; v < views; ++v)
      if (auto s = sight(in, v, surface, hit.primitive)) seen.push_back(*s);
    // Observations: exact projection plus keypoint noise; a keypoint pushed out of the image is lost.
    std::vector<std::pair<int, Vec2>> observations;
    for (const Sighting& s : seen) {
      const Vec2 xy{s.xy[0] + in.spec.observation_noise_px * rng.normal(),
                    s.xy[1] + in.spec.observation_noise_px * rng.normal()};
      if (xy[0] >= 0 && xy[1] >= 0 && xy[0] < w && xy[1] < h) observations.emplace_back(s.view, xy);
    }
    if (static_cast<int>(observations.size()) < in.spec.min_track) continue;

    // Position noise in world units that reprojects to ≈ position_noise_px at the median depth.
    std::vector<double> depths;
    for (const Sighting& s : seen) depths.push_back(s.depth);
    const double sigma = in.spec.position_noise_px * median(std::move(depths)) / focal;
    const Vec3 stored = surface + sigma * Vec3(rng.normal(), rng.normal(), rng.normal());

    colmap::Point3D point;
    point.id = next_id++;
    point.xyz = {stored.x(), stored.y(), stored.z()};
    const Color c = in.statics->shade(hit);
    point.rgb = {to_byte(c.x()), to_byte(c.y()), to_byte(c.z())};
    double error = 0;
    for (const auto& [v, xy] : observations) {
      colmap::Image& image = model.images.at(static_cast<uint32_t>(v + 1));
      point.track.push_back({image.id, static_cast<uint32_t>(image.points2d.size())});
      image.points2d.push_back({xy[0], xy[1], static_cast<int64_t>(point.id)});
      const Vec2 p = project(in, v, stored);
      error += std::hypot(p[0] - xy[0], p[1] - xy[1]);
    }
    point.error = error / static_cast<double>(observations.size());
    model.points.emplace(point.id, std::move(point));
  }
}

}  // namespace desplat::synth
