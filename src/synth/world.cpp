// Ray intersection, procedural textures and lighting of the synthetic world.
#include "synth/world.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "synth/random.hpp"

namespace desplat::synth {
namespace {

constexpr double kTMin = 1e-9;  // rays start at a camera, never on a surface

Vec3 to_vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

// A fixed lattice of random values (Perlin's permutation trick): cheaper than hashing every
// corner, and the 256-cell period is far beyond any pattern scale we use.
struct NoiseLattice {
  std::array<uint8_t, 512> perm{};
  std::array<double, 256> value{};
  NoiseLattice() {
    Rng rng(0x5EED, Stream::Jitter);  // fixed: textures do not change with the scene's seed
    for (int i = 0; i < 256; ++i) {
      perm[static_cast<size_t>(i)] = static_cast<uint8_t>(i);
      value[static_cast<size_t>(i)] = rng.uniform();
    }
    for (int i = 255; i > 0; --i) std::swap(perm[static_cast<size_t>(i)], perm[static_cast<size_t>(rng.integer(0, i))]);
    for (size_t i = 0; i < 256; ++i) perm[i + 256] = perm[i];
  }
  double at(int64_t x, int64_t y, int64_t z) const {
    const auto p = [&](int64_t a) { return static_cast<size_t>(perm[static_cast<size_t>(a)]); };
    return value[p(static_cast<int64_t>(p(static_cast<int64_t>(p(x & 255)) + (y & 255))) + (z & 255))];
  }
};

// Value noise on the integer lattice, trilinearly interpolated with a smooth fade: in [0, 1].
double value_noise(const Vec3& p) {
  static const NoiseLattice lattice;
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const auto ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy), iz = static_cast<int64_t>(fz);
  const auto fade = [](double w) { return w * w * (3 - 2 * w); };
  const double sx = fade(p.x() - fx), sy = fade(p.y() - fy), sz = fade(p.z() - fz);
  double v[2][2];
  for (int dy = 0; dy < 2; ++dy)
    for (int dz = 0; dz < 2; ++dz) {
      const double a = lattice.at(ix, iy + dy, iz + dz), b = lattice.at(ix + 1, iy + dy, iz + dz);
      v[dy][dz] = a + sx * (b - a);
    }
  const double a = v[0][0] + sy * (v[1][0] - v[0][0]);
  const double b = v[0][1] + sy * (v[1][1] - v[0][1]);
  return a + sz * (b - a);
}

// Four octaves of value noise: detail at several scales for feature matching; ≈ [0, 1], mean 0.5.
double fbm(const Vec3& p) {
  double sum = 0, amplitude = 0.5, norm = 0;
  Vec3 q = p;
  for (int octave = 0; octave < 4; ++octave) {
    sum += amplitude * value_noise(q);
    norm += amplitude;
    amplitude *= 0.5;
    q = 2.03 * q + Vec3(17.1, 5.3, 11.7);  // offset so octaves do not share lattice points
  }
  return sum / norm;
}

bool odd(double x) { return (static_cast<int64_t>(std::floor(x)) & 1) != 0; }

}  // namespace

Color texture_albedo(const TextureSpec& t, const Vec3& coord) {
  const Color a = to_vec(t.color_a), b = to_vec(t.color_b);
  const Vec3 p = coord * t.scale;
  Color c = a;
  if (t.kind == "checker") {
    c = odd(p.x()) ^ odd(p.y()) ^ odd(p.z()) ? b : a;
  } else if (t.kind == "stripes") {
    c = odd(p.x() + 0.5 * p.y() + 0.25 * p.z()) ? b : a;
  } else if (t.kind == "noise") {
    const double m = std::clamp(1.6 * (fbm(p) - 0.5) + 0.5, 0.0, 1.0);  // stretched for contrast
    c = a + m * (b - a);
  }
  if (t.detail > 0) c *= (1 - t.detail) + t.detail * 2 * fbm(4.1 * p + Vec3(3.7, 1.9, 8.3));
  return c.cwiseMax(0.0).cwiseMin(1.0);
}

Primitive make_primitive(const ObjectSpec& spec) {
  Primitive p;
  p.center = to_vec(spec.center);
  p.texture = spec.texture;
  const double yaw = spec.yaw_deg * std::numbers::pi / 180;
  if (spec.shape == "sphere") {
    p.shape = Primitive::Shape::Sphere;
    p.half = Vec3(spec.radius, spec.radius, spec.radius);
  } else if (spec.shape == "box") {
    p.shape = Primitive::Shape::Box;
    p.half = 0.5 * to_vec(spec.size);
    p.to_local = Eigen::AngleAxisd(yaw, Vec3::UnitZ()).toRotationMatrix().transpose();
  } else {
    p.shape = Primitive::Shape::Plane;
    p.half = 0.5 * to_vec(spec.size);
    const Vec3 n = to_vec(spec.normal).normalized();
    // Tangents: world x projected onto the plane, or world y when the normal is along x.
    const Vec3 ref = std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    Vec3 t1 = (ref - ref.dot(n) * n).normalized();
    t1 = Eigen::AngleAxisd(yaw, n) * t1;
    p.to_local.row(0) = t1.transpose();
    p.to_local.row(1) = n.cross(t1).transpose();
    p.to_local.row(2) = n.transpose();
  }
  p.bound_radius2 = p.shape == Primitive::Shape::Plane ? p.half.head<2>().squaredNorm() : p.half.squaredNorm();
  p.unbounded = p.shape == Primitive::Shape::Plane;  // a ground plane fills most views anyway
  return p;
}

Primitives::Primitives(std::vector<Primitive> items, const LightSpec& light)
    : items_(std::move(items)), light_dir_(to_vec(light.direction).normalized()), ambient_(light.ambient) {}

Hit Primitives::nearest(const Ray& ray, double t_max) const {
  Hit best;
  best.t = t_max;
  for (size_t i = 0; i < items_.size(); ++i) {
    const Primitive& p = items_[i];
    if (!p.unbounded) {  // cheap reject: the ray misses the bounding sphere or it lies behind
      const Vec3 oc = p.center - ray.origin;
      const double along = oc.dot(ray.dir);
      if (oc.squaredNorm() - along * along > p.bound_radius2 || (along < 0 && oc.squaredNorm() > p.bound_radius2) ||
          along - std::sqrt(p.bound_radius2) >= best.t)
        continue;
    }
    const Vec3 o = p.to_local * (ray.origin - p.center);  // ray in the object's frame
    const Vec3 d = p.to_local * ray.dir;
    double t = best.t;
    Vec3 local_normal, coord;
    if (p.shape == Primitive::Shape::Sphere) {
      const double r = p.half.x(), b = o.dot(d), c = o.squaredNorm() - r * r, disc = b * b - c;
      if (disc < 0) continue;
      const double sq = std::sqrt(disc);
      t = -b - sq > kTMin ? -b - sq : -b + sq;
      if (t <= kTMin || t >= best.t) continue;
      coord = o + t * d;
      local_normal = coord / r;
    } else if (p.shape == Primitive::Shape::Plane) {
      if (std::abs(d.z()) < 1e-12) continue;
      t = -o.z() / d.z();
      if (t <= kTMin || t >= best.t) continue;
      const Vec3 q = o + t * d;
      if (std::abs(q.x()) > p.half.x() || std::abs(q.y()) > p.half.y()) continue;
      coord = Vec3(q.x(), q.y(), 0);
      local_normal = Vec3::UnitZ();
    } else {  // box: slabs
      double t0 = kTMin, t1 = best.t;
      int axis = -1;
      for (int a = 0; a < 3; ++a) {
        if (std::abs(d[a]) < 1e-15) {  // parallel to this slab: inside it or a miss
          if (std::abs(o[a]) > p.half[a]) t0 = t1 + 1;
          if (t0 > t1) break;
          continue;
        }
        double near = (-p.half[a] - o[a]) / d[a], far = (p.half[a] - o[a]) / d[a];
        if (near > far) std::swap(near, far);
        if (near > t0) {
          t0 = near;
          axis = a;
        }
        t1 = std::min(t1, far);
        if (t0 > t1) break;
      }
      if (t0 > t1 || axis < 0) continue;  // missed, or the ray starts inside the box
      t = t0;
      const Vec3 q = o + t * d;
      local_normal = Vec3::Zero();
      local_normal[axis] = d[axis] < 0 ? 1 : -1;
      // Texture on the face's own two axes (a face lies on a lattice plane otherwise, where the
      // pattern would flicker); the third coordinate tells the faces apart.
      coord = q;
      coord[axis] = 7.31 * axis + (local_normal[axis] > 0 ? 3.17 : 0);
    }
    best.t = t;
    best.primitive = static_cast<int>(i);
    best.texture_coord = coord;
    Vec3 n = p.to_local.transpose() * local_normal;
    best.normal = n.dot(ray.dir) > 0 ? Vec3(-n) : n;  // two-sided surfaces
  }
  if (best.primitive < 0) best.t = std::numeric_limits<double>::infinity();
  return best;
}

Color Primitives::shade(const Hit& hit) const {
  const Primitive& p = items_[static_cast<size_t>(hit.primitive)];
  const double lambert = std::max(0.0, hit.normal.dot(light_dir_));
  return texture_albedo(p.texture, hit.texture_coord) * (ambient_ + (1 - ambient_) * lambert);
}

Color background_color(const WorldSpec& world, const SkySpec& sky, const Vec3& dir) {
  if (!sky.enabled) return to_vec(world.background);
  const Color horizon = to_vec(sky.horizon), zenith = to_vec(sky.zenith);
  const double up = dir.z();
  if (up <= 0) return horizon * (1 - 0.3 * std::min(1.0, -4 * up));  // below the horizon: haze
  Color c = horizon + std::sqrt(up) * (zenith - horizon);
  // Clouds on a plane above the camera, seen through the direction only (so: at infinity).
  const Vec3 on_plane(dir.x() / (up + 0.15), dir.y() / (up + 0.15), 0.5);
  const double density = std::clamp((fbm(2.5 * on_plane) - (1 - sky.clouds)) * 3, 0.0, 1.0);
  const double fade = std::min(1.0, 6 * up);
  return c + density * fade * (Color(0.96, 0.96, 0.96) - c);
}

}  // namespace desplat::synth
