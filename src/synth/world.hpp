// The generator's geometry: textured primitives (finite planes, oriented boxes, spheres),
// ray intersection, procedural textures and simple lighting (Lambert + ambient, no shadows,
// so colors do not depend on the viewpoint), and the sky at infinity.
// World units and frame as synth.hpp (z up). Plain values, read-only after construction, so
// one World is shared by all rendering threads.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <vector>

#include "desplat/synth/synth.hpp"

namespace desplat::synth {

using Vec3 = Eigen::Vector3d;
using Color = Eigen::Vector3d;  // RGB in [0, 1]

struct Ray {
  Vec3 origin;
  Vec3 dir;  // unit length
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();  // distance along the ray
  int primitive = -1;                                  // -1: nothing hit
  Vec3 normal{0, 0, 1};                                // unit, facing the ray
  Vec3 texture_coord{0, 0, 0};                         // object-local, see Primitive
  bool hit() const { return primitive >= 0; }
};

struct Primitive {
  enum class Shape { Plane, Box, Sphere } shape = Shape::Box;
  Vec3 center{0, 0, 0};
  Eigen::Matrix3d to_local = Eigen::Matrix3d::Identity();  // rows: the object's axes in world
                                                           // (plane: tangent 1, tangent 2, normal)
  Vec3 half{0.5, 0.5, 0.5};  // box: half extents; plane: half sizes in x, y; sphere: radius in x
  TextureSpec texture;
  double bound_radius2 = 0;  // squared radius of a sphere around center holding the primitive
  bool unbounded = false;    // skip the bounding-sphere test
};

Primitive make_primitive(const ObjectSpec& spec);

// A set of primitives lit by one light: the static world, or one view's distractors.
class Primitives {
 public:
  Primitives() = default;
  Primitives(std::vector<Primitive> items, const LightSpec& light);

  // The nearest hit with t in (t_min, t_max).
  Hit nearest(const Ray& ray, double t_max = std::numeric_limits<double>::infinity()) const;
  // The lit surface color at a hit of this set.
  Color shade(const Hit& hit) const;
  bool empty() const { return items_.empty(); }

 private:
  std::vector<Primitive> items_;
  Vec3 light_dir_{0, 0, 1};
  double ambient_ = 0.35;
};

// The texture's albedo at object-local texture coordinates (exposed for the distractors).
Color texture_albedo(const TextureSpec& texture, const Vec3& coord);

// The color of a ray that escapes to infinity: the sky if enabled, else the background.
Color background_color(const WorldSpec& world, const SkySpec& sky, const Vec3& dir);

}  // namespace desplat::synth
