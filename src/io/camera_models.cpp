// COLMAP's camera models: each model is a distortion on the camera plane plus a pinhole
// matrix; the table at the bottom turns each into a pair of projection functions.
#include "desplat/io/camera_models.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace desplat {
namespace {

using colmap::CameraModelId;

constexpr double kEps = std::numeric_limits<double>::epsilon();

// ---- Distortions (camera plane -> offset on the camera plane) -----------------------------
// Each model: kFocal (1 or 2 focal parameters) and distortion(extra, w) returning the offset
// d so that the distorted point is w + d. Optional members: warp/unwarp (a mapping applied
// before distortion) and inverse (a closed-form undistortion).

struct SimplePinhole {
  static constexpr int kFocal = 1;
  static Vec2 distortion(const double*, Vec2) { return {0, 0}; }
  static Vec2 inverse(const double*, Vec2 w) { return w; }
};

struct Pinhole {
  static constexpr int kFocal = 2;
  static Vec2 distortion(const double*, Vec2) { return {0, 0}; }
  static Vec2 inverse(const double*, Vec2 w) { return w; }
};

// Radial polynomial k1·r² + k2·r⁴ + … with the tangential terms of Brown–Conrady.
Vec2 radial_tangential(Vec2 w, double radial, double p1, double p2) {
  const double u = w[0], v = w[1];
  const double r2 = u * u + v * v;
  return {u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u), v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)};
}

double radius2(Vec2 w) { return w[0] * w[0] + w[1] * w[1]; }

struct SimpleRadial {
  static constexpr int kFocal = 1;
  static Vec2 distortion(const double* k, Vec2 w) { return radial_tangential(w, k[0] * radius2(w), 0, 0); }
};

struct Radial {
  static constexpr int kFocal = 1;
  static Vec2 distortion(const double* k, Vec2 w) {
    const double r2 = radius2(w);
    return radial_tangential(w, k[0] * r2 + k[1] * r2 * r2, 0, 0);
  }
};

struct OpenCV {  // k1, k2, p1, p2
  static constexpr int kFocal = 2;
  static Vec2 distortion(const double* k, Vec2 w) {
    const double r2 = radius2(w);
    return radial_tangential(w, k[0] * r2 + k[1] * r2 * r2, k[2], k[3]);
  }
};

struct FullOpenCV {  // k1, k2, p1, p2, k3, k4, k5, k6 (rational radial term)
  static constexpr int kFocal = 2;
  static Vec2 distortion(const double* k, Vec2 w) {
    const double r2 = radius2(w), r4 = r2 * r2, r6 = r4 * r2;
    const double radial = (1 + k[0] * r2 + k[1] * r4 + k[4] * r6) / (1 + k[5] * r2 + k[6] * r4 + k[7] * r6);
    const Vec2 d = radial_tangential(w, radial, k[2], k[3]);
    return {d[0] - w[0], d[1] - w[1]};
  }
};

// Equidistant fisheye: the point at angle θ = atan(r) from the axis lands at radius
// θ·(1 + k1·θ² + k2·θ⁴ + …) on the plane; `poly` is that bracket.
template <class Poly>
Vec2 fisheye_offset(Vec2 w, Poly poly) {
  const double r = std::sqrt(radius2(w));
  if (!(r > kEps)) return {0, 0};
  const double theta = std::atan(r);
  const double factor = theta * poly(theta * theta) / r - 1;
  return {w[0] * factor, w[1] * factor};
}

struct OpenCVFisheye {  // k1, k2, k3, k4
  static constexpr int kFocal = 2;
  static Vec2 distortion(const double* k, Vec2 w) {
    return fisheye_offset(w, [k](double t2) { return 1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))); });
  }
};

struct SimpleRadialFisheye {  // k
  static constexpr int kFocal = 1;
  static Vec2 distortion(const double* k, Vec2 w) {
    return fisheye_offset(w, [k](double t2) { return 1 + k[0] * t2; });
  }
};

struct RadialFisheye {  // k1, k2
  static constexpr int kFocal = 1;
  static Vec2 distortion(const double* k, Vec2 w) {
    return fisheye_offset(w, [k](double t2) { return 1 + t2 * (k[0] + t2 * k[1]); });
  }
};

// FOV (Devernay–Faugeras), omega. COLMAP evaluates the factor with Taylor expansions near
// ω = 0 and r = 0; kept, so that results match COLMAP's to the last bits there too.
struct FOV {
  static constexpr int kFocal = 2;
  static double distort_factor(double omega, double r2) {
    const double omega2 = omega * omega;
    if (omega2 < 1e-4) return omega2 * r2 / 3 - omega2 / 12 + 1;
    const double t = std::tan(omega / 2);
    if (r2 < 1e-4) return -2 * t * (4 * r2 * t * t - 3) / (3 * omega);
    const double r = std::sqrt(r2);
    return std::atan(r * 2 * t) / (r * omega);
  }
  static double undistort_factor(double omega, double r2) {
    const double omega2 = omega * omega;
    if (omega2 < 1e-4) return omega2 * r2 / 3 - omega2 / 12 + 1;
    if (r2 < 1e-4) return omega * (omega2 * r2 + 3) / (6 * std::tan(omega / 2));
    const double r = std::sqrt(r2);
    return std::tan(r * omega) / (r * 2 * std::tan(omega / 2));
  }
  static Vec2 distortion(const double* k, Vec2 w) {
    const double f = distort_factor(k[0], radius2(w)) - 1;
    return {w[0] * f, w[1] * f};
  }
  static Vec2 inverse(const double* k, Vec2 w) {
    const double f = undistort_factor(k[0], radius2(w));
    return {w[0] * f, w[1] * f};
  }
};

// Thin-prism fisheye: k1, k2, p1, p2, k3, k4, sx1, sy1, applied to the equidistant point
// θ·(u, v)/r rather than to (u, v).
struct ThinPrismFisheye {
  static constexpr int kFocal = 2;
  static Vec2 warp(Vec2 uv) {
    const double r = std::sqrt(radius2(uv));
    if (!(r > kEps)) return uv;
    const double s = std::atan(r) / r;
    return {uv[0] * s, uv[1] * s};
  }
  static Vec2 unwarp(Vec2 w) {
    const double theta = std::sqrt(radius2(w));
    const double theta_cos = theta * std::cos(theta);
    if (!(theta_cos > kEps)) return w;
    const double s = std::sin(theta) / theta_cos;
    return {w[0] * s, w[1] * s};
  }
  static Vec2 distortion(const double* k, Vec2 w) {
    const double r2 = radius2(w), r4 = r2 * r2, r6 = r4 * r2, r8 = r6 * r2;
    const double radial = k[0] * r2 + k[1] * r4 + k[4] * r6 + k[5] * r8;
    const Vec2 d = radial_tangential(w, radial, k[2], k[3]);
    return {d[0] + k[6] * r2, d[1] + k[7] * r2};
  }
};

// ---- Generic projection ---------------------------------------------------------------------

// Solves w + D(w) = target for w by Newton's method, the Jacobian by central differences.
template <class Model>
Vec2 newton_undistort(const double* extra, Vec2 target) {
  Vec2 w = target;
  for (int iter = 0; iter < 100; ++iter) {
    const Vec2 d = Model::distortion(extra, w);
    const double rx = w[0] + d[0] - target[0], ry = w[1] + d[1] - target[1];
    double J[2][2];
    for (int k = 0; k < 2; ++k) {
      const double h = 1e-6 * (1 + std::abs(w[k]));
      Vec2 lo = w, hi = w;
      lo[k] -= h;
      hi[k] += h;
      const Vec2 d_lo = Model::distortion(extra, lo), d_hi = Model::distortion(extra, hi);
      J[0][k] = (k == 0 ? 1.0 : 0.0) + (d_hi[0] - d_lo[0]) / (2 * h);
      J[1][k] = (k == 1 ? 1.0 : 0.0) + (d_hi[1] - d_lo[1]) / (2 * h);
    }
    const double det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
    if (!(std::abs(det) > 0)) break;  // singular: the distortion folds here
    const double sx = (J[1][1] * rx - J[0][1] * ry) / det;
    const double sy = (J[0][0] * ry - J[1][0] * rx) / det;
    w[0] -= sx;
    w[1] -= sy;
    if (sx * sx + sy * sy < 1e-26) break;
  }
  return w;
}

template <class Model>
PinholeIntrinsics intrinsics_of(const double* p) {
  if constexpr (Model::kFocal == 1)
    return {p[0], p[0], p[1], p[2]};
  else
    return {p[0], p[1], p[2], p[3]};
}

template <class Model>
Vec2 project(const double* params, Vec2 uv) {
  const PinholeIntrinsics K = intrinsics_of<Model>(params);
  const double* extra = params + Model::kFocal + 2;
  Vec2 w = uv;
  if constexpr (requires { Model::warp(uv); }) w = Model::warp(uv);
  const Vec2 d = Model::distortion(extra, w);
  return {K.fx * (w[0] + d[0]) + K.cx, K.fy * (w[1] + d[1]) + K.cy};
}

template <class Model>
Vec2 unproject(const double* params, Vec2 xy) {
  const PinholeIntrinsics K = intrinsics_of<Model>(params);
  const double* extra = params + Model::kFocal + 2;
  const Vec2 distorted{(xy[0] - K.cx) / K.fx, (xy[1] - K.cy) / K.fy};
  Vec2 w;
  if constexpr (requires { Model::inverse(extra, distorted); })
    w = Model::inverse(extra, distorted);
  else
    w = newton_undistort<Model>(extra, distorted);
  if constexpr (requires { Model::unwarp(w); }) w = Model::unwarp(w);
  return w;
}

template <class Model>
constexpr CameraModelMath row(CameraModelId id, bool has_distortion) {
  return {id, Model::kFocal, has_distortion, &project<Model>, &unproject<Model>};
}

// Indexed by model id.
constexpr CameraModelMath kModels[] = {
    row<SimplePinhole>(CameraModelId::SimplePinhole, false),
    row<Pinhole>(CameraModelId::Pinhole, false),
    row<SimpleRadial>(CameraModelId::SimpleRadial, true),
    row<Radial>(CameraModelId::Radial, true),
    row<OpenCV>(CameraModelId::OpenCV, true),
    row<OpenCVFisheye>(CameraModelId::OpenCVFisheye, true),
    row<FullOpenCV>(CameraModelId::FullOpenCV, true),
    row<FOV>(CameraModelId::FOV, true),
    row<SimpleRadialFisheye>(CameraModelId::SimpleRadialFisheye, true),
    row<RadialFisheye>(CameraModelId::RadialFisheye, true),
    row<ThinPrismFisheye>(CameraModelId::ThinPrismFisheye, true),
};

// The model's row after checking that the camera's params fit it.
const CameraModelMath& checked_math(const colmap::Camera& camera) {
  const CameraModelMath& math = camera_model_math(camera.model);
  const int expected = colmap::camera_model_info(camera.model).num_params;
  if (camera.params.size() != static_cast<size_t>(expected))
    throw std::invalid_argument("camera " + std::to_string(camera.id) + ": " +
                                colmap::camera_model_info(camera.model).name + " needs " + std::to_string(expected) +
                                " params, got " + std::to_string(camera.params.size()));
  return math;
}

}  // namespace

const CameraModelMath& camera_model_math(CameraModelId id) {
  const int index = static_cast<int>(id);
  if (index < 0 || index >= static_cast<int>(std::size(kModels)))
    throw std::invalid_argument("unknown COLMAP camera model id " + std::to_string(index));
  return kModels[index];
}

Vec2 image_from_camera(const colmap::Camera& camera, Vec2 uv) {
  return checked_math(camera).image_from_camera(camera.params.data(), uv);
}

Vec2 camera_from_image(const colmap::Camera& camera, Vec2 xy) {
  return checked_math(camera).camera_from_image(camera.params.data(), xy);
}

PinholeIntrinsics pinhole_intrinsics(const colmap::Camera& camera) {
  const double* p = camera.params.data();
  if (checked_math(camera).num_focal == 1) return {p[0], p[0], p[1], p[2]};
  return {p[0], p[1], p[2], p[3]};
}

colmap::Camera rescale_camera(const colmap::Camera& camera, uint64_t width, uint64_t height) {
  const int num_focal = checked_math(camera).num_focal;
  if (camera.width == 0 || camera.height == 0 || width == 0 || height == 0)
    throw std::invalid_argument("rescale_camera: camera " + std::to_string(camera.id) +
                                ": image sizes must be positive");
  const double sx = static_cast<double>(width) / static_cast<double>(camera.width);
  const double sy = static_cast<double>(height) / static_cast<double>(camera.height);
  colmap::Camera out = camera;
  if (num_focal == 1) {
    out.params[0] *= (sx + sy) / 2;
  } else {
    out.params[0] *= sx;
    out.params[1] *= sy;
  }
  out.params[num_focal] *= sx;
  out.params[num_focal + 1] *= sy;
  out.width = width;
  out.height = height;
  return out;
}

}  // namespace desplat
