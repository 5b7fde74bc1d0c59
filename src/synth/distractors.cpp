// Random per-view distractor objects and the choice of cluttered views.
#include "synth/distractors.hpp"

#include <Eigen/Geometry>
#include <cmath>

#include "desplat/io/camera_models.hpp"
#include "synth/random.hpp"

namespace desplat::synth {

std::vector<bool> cluttered_views(int count, double clutter_ratio) {
  std::vector<bool> cluttered(static_cast<size_t>(count), false);
  std::vector<int> train;
  for (int k = 0; k < count; ++k)
    if (!is_test_view(k)) train.push_back(k);
  const auto n = static_cast<int64_t>(train.size());
  const auto m = static_cast<int64_t>(std::llround(clutter_ratio * static_cast<double>(n)));
  for (int64_t j = 0; j < n; ++j)
    if ((j + 1) * m / n > j * m / n) cluttered[static_cast<size_t>(train[static_cast<size_t>(j)])] = true;
  return cluttered;
}

namespace {

// A saturated color of random hue: distractors should look unlike the muted static scene.
Rgb vivid_color(Rng& rng) {
  const double h = rng.uniform() * 6;
  const double x = 1 - std::abs(std::fmod(h, 2.0) - 1);
  const int sector = static_cast<int>(h);
  const std::array<Rgb, 6> table{{{1, x, 0}, {x, 1, 0}, {0, 1, x}, {0, x, 1}, {x, 0, 1}, {1, 0, x}}};
  Rgb c = table[static_cast<size_t>(std::min(sector, 5))];
  const double lo = rng.uniform(0.05, 0.25), hi = rng.uniform(0.8, 1.0);
  for (double& v : c) v = lo + (hi - lo) * v;
  return c;
}

}  // namespace

std::vector<Primitive> make_distractors(const DistractorSpec& spec, const ViewPose& pose, const colmap::Camera& lens,
                                        uint64_t seed, int view) {
  Rng rng(seed, Stream::Distractors, static_cast<uint64_t>(view));
  const double distance = (pose.target - pose.center).norm();
  const PinholeIntrinsics K = pinhole_intrinsics(lens);
  const auto w = static_cast<double>(lens.width), h = static_cast<double>(lens.height);
  const int count = rng.integer(spec.per_view[0], spec.per_view[1]);
  std::vector<Primitive> out;
  for (int i = 0; i < count; ++i) {
    const double depth = rng.uniform(spec.depth[0], spec.depth[1]) * distance;
    const Vec2 pixel{rng.uniform(0.15, 0.85) * w, rng.uniform(0.15, 0.85) * h};
    const Vec2 uv = camera_from_image(lens, pixel);
    const Eigen::Vector3d p_cam(uv[0] * depth, uv[1] * depth, depth);
    const double diameter = rng.uniform(spec.size[0], spec.size[1]) * h * depth / K.fy;

    ObjectSpec o;
    const Eigen::Vector3d p_world = pose.R_cw.transpose() * (p_cam - pose.t_cw);
    o.center = {p_world.x(), p_world.y(), p_world.z()};
    o.shape = rng.uniform() < 0.5 ? "sphere" : "box";
    o.radius = 0.5 * diameter;
    for (double& e : o.size) e = diameter * rng.uniform(0.55, 1.0);
    const std::array<const char*, 3> kinds{"checker", "stripes", "noise"};
    o.texture.kind = kinds[static_cast<size_t>(rng.integer(0, 2))];
    o.texture.color_a = vivid_color(rng);
    o.texture.color_b = vivid_color(rng);
    o.texture.scale = rng.uniform(3, 6) / diameter;  // a few pattern cells across the object
    o.texture.detail = 0.2;
    Primitive p = make_primitive(o);
    // Any orientation: a uniformly random rotation from a normalized Gaussian quaternion, taken
    // in the camera's frame so that views drawing the same stream see the same silhouette
    // (Eigen, as the scene loader's rotations, to keep the generated scenes' bits).
    const Eigen::Quaterniond q(rng.normal(), rng.normal(), rng.normal(), rng.normal());
    p.to_local = q.normalized().toRotationMatrix() * pose.R_cw;
    out.push_back(p);
  }
  return out;
}

}  // namespace desplat::synth
