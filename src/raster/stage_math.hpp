// The math of every rasterization stage, one function per stage, each written once as
// a template over the scalar type: the kernels instantiate it with float, the tests
// with double (reference) and ceres::Jet (exact derivatives). The hand-written
// vector–Jacobian products (`*_vjp`, float) sit next to the function they invert.
// Equations: docs/METHOD.md §2–3.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "desplat/core/spherical_harmonics.hpp"

namespace desplat::raster {

// a·b + c. For float on a CPU with FMA, one fused instruction (one rounding): the code is
// built with contraction on, and the α of a Gaussian at a pixel must come out bit-identical
// in the forward and the backward pass, so the α path spells its fusions out instead of
// leaving them to the compiler (which fuses a product only where it has a single use).
template <typename T>
T madd(T a, T b, T c) {
  return a * b + c;
}
#ifdef __FMA__
template <>
inline float madd(float a, float b, float c) {
  return std::fma(a, b, c);
}
#endif

template <typename T>
using Vec2 = Eigen::Matrix<T, 2, 1>;
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Vec4 = Eigen::Matrix<T, 4, 1>;
template <typename T>
using Mat2 = Eigen::Matrix<T, 2, 2>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Mat23 = Eigen::Matrix<T, 2, 3>;

constexpr float kAlphaMax = 0.999f;
constexpr float kAlphaMin = 1.0f / 255.0f;
constexpr float kTransmittanceMin = 1e-4f;
constexpr float kExtentSigmas = 3.33f;

// Sigmas out to which a Gaussian of opacity o can still reach α ≥ 1/255: σ = ½dᵀΣ⁻¹d ≤
// ln(255·o), i.e. √(2·ln(255·o)) standard deviations along each axis (gsplat does the same).
// 0.01 is added to ln(255·o) as a margin for float rounding (α at the edge ≤ 0.99/255),
// and the result never exceeds kExtentSigmas, the opacity-free box. 0 when o < 1/255:
// such a Gaussian is never blended anywhere.
inline float opacity_extent_sigmas(float opacity) {
  const float s = std::log(255.0f * opacity) + 0.01f;
  if (!(s > 0.0f)) return 0.0f;
  return std::min(kExtentSigmas, std::sqrt(2.0f * s));
}
// Radii are clamped here before conversion to int; a Gaussian whose center lies
// further than this outside the image is culled (its squared offsets would overflow).
constexpr float kMaxRadius = 1 << 20;
// Below this norm a quaternion's gradient is computed as if it had this norm, so the
// gradient stays finite (the exact one, ∝ 1/|q|, overflows float32 for tiny |q|).
constexpr float kMinQuatNorm = 1e-8f;

// --- opacity -------------------------------------------------------------------
template <typename T>
T sigmoid(T x) {
  using std::exp;
  if (x >= T(0)) return T(1) / (T(1) + exp(-x));
  const T e = exp(x);
  return e / (T(1) + e);
}

// --- rotation from quaternion (w, x, y, z) ----------------------------------------
// Normalizes after dividing by the largest component, so denormal quaternions keep
// their direction; an all-zero (or non-finite) quaternion maps to the identity.
template <typename T>
Vec4<T> normalize_quat(const T* q) {
  using std::abs;
  using std::sqrt;
  T m = abs(q[0]);
  for (int i = 1; i < 4; ++i) m = std::max(m, T(abs(q[i])));
  if (!(m > T(0)) || !(m < T(INFINITY))) return Vec4<T>(T(1), T(0), T(0), T(0));
  Vec4<T> u(q[0] / m, q[1] / m, q[2] / m, q[3] / m);
  return u / sqrt(u.squaredNorm());
}

template <typename T>
Mat3<T> rotation_from_unit_quat(const Vec4<T>& q) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  Mat3<T> R;
  R << T(1) - T(2) * (y * y + z * z), T(2) * (x * y - w * z), T(2) * (x * z + w * y), T(2) * (x * y + w * z),
      T(1) - T(2) * (x * x + z * z), T(2) * (y * z - w * x), T(2) * (x * z - w * y), T(2) * (y * z + w * x),
      T(1) - T(2) * (x * x + y * y);
  return R;
}

// ∂L/∂q (raw quaternion) from ∂L/∂R.
Vec4<float> quat_vjp(const float* q_raw, const Mat3<float>& dR);

// --- 3D covariance Σ = R S Sᵀ Rᵀ, S = diag(exp(s)) ---------------------------------
template <typename T>
Mat3<T> covariance_3d(const T* log_scale, const T* quat) {
  using std::exp;
  const Mat3<T> R = rotation_from_unit_quat<T>(normalize_quat<T>(quat));
  Mat3<T> M = R;
  for (int j = 0; j < 3; ++j) M.col(j) *= exp(log_scale[j]);
  return M * M.transpose();
}

// ∂L/∂s and ∂L/∂q from ∂L/∂Σ (full 3×3 gradient; symmetrized here).
void covariance_3d_vjp(const float* log_scale, const float* quat, const Mat3<float>& dSigma, float* d_log_scale,
                       float* d_quat);

// --- EWA projection ----------------------------------------------------------------
struct PinholeIntrinsics {
  float fx, fy, cx, cy;
  int width, height;
};

// How far x/z and y/z may reach before the projection's Jacobian clamps them: the image's
// field of view widened by 30 % of its half-width tangent on each side (in double, as every
// caller casts it).
struct FovLimits {
  double x_pos, x_neg, y_pos, y_neg;
};
inline FovLimits fov_limits(const PinholeIntrinsics& K) {
  const double tan_fovx = 0.5 * K.width / K.fx, tan_fovy = 0.5 * K.height / K.fy;
  return {(K.width - K.cx) / K.fx + 0.3 * tan_fovx, K.cx / K.fx + 0.3 * tan_fovx,
          (K.height - K.cy) / K.fy + 0.3 * tan_fovy, K.cy / K.fy + 0.3 * tan_fovy};
}

template <typename T>
struct Projection {
  Vec2<T> mean2d;  // [px]
  Mat2<T> cov2d;   // with the eps2d blur [px²]
  T depth;         // camera z
};

// Camera-space point p, camera-space covariance V. Caller culls p.z outside
// (near, far) first.
template <typename T>
Projection<T> project_ewa(const Vec3<T>& p, const Mat3<T>& V, const PinholeIntrinsics& K, float eps2d) {
  const T x = p[0], y = p[1], z = p[2];
  const T rz = T(1) / z;
  const FovLimits lim = fov_limits(K);
  const T lim_x_pos = T(lim.x_pos), lim_x_neg = T(lim.x_neg);
  const T lim_y_pos = T(lim.y_pos), lim_y_neg = T(lim.y_neg);
  const T tx = z * std::min(lim_x_pos, std::max(T(-lim_x_neg), T(x * rz)));
  const T ty = z * std::min(lim_y_pos, std::max(T(-lim_y_neg), T(y * rz)));
  Mat23<T> J;
  J << T(K.fx) * rz, T(0), T(-K.fx) * tx * rz * rz, T(0), T(K.fy) * rz, T(-K.fy) * ty * rz * rz;
  Projection<T> out;
  out.cov2d = J * V * J.transpose();
  out.cov2d(0, 0) += T(eps2d);
  out.cov2d(1, 1) += T(eps2d);
  out.mean2d = Vec2<T>(T(K.fx) * x * rz + T(K.cx), T(K.fy) * y * rz + T(K.cy));
  out.depth = z;
  return out;
}

// ∂L/∂p and ∂L/∂V from ∂L/∂mean2d, ∂L/∂cov2d (full 2×2) and ∂L/∂depth.
void project_ewa_vjp(const Vec3<float>& p, const Mat3<float>& V, const PinholeIntrinsics& K,
                     const Vec2<float>& d_mean2d, const Mat2<float>& d_cov2d, float d_depth, Vec3<float>& d_p,
                     Mat3<float>& d_V);

// Conic (a, b, c) = entries (0,0), (0,1), (1,1) of cov2d⁻¹.
template <typename T>
Vec3<T> conic_from_cov2d(const Mat2<T>& cov, T* det_out = nullptr) {
  const T det = cov(0, 0) * cov(1, 1) - cov(0, 1) * cov(1, 0);
  if (det_out) *det_out = det;
  const T inv = T(1) / det;
  return Vec3<T>(cov(1, 1) * inv, -cov(0, 1) * inv, cov(0, 0) * inv);
}

// ∂L/∂cov2d (full 2×2) from ∂L/∂(a, b, c).
Mat2<float> conic_vjp(const Vec3<float>& conic, const Vec3<float>& d_conic);

// --- per-pixel falloff -----------------------------------------------------------
// d = μ2d − pixel center.
template <typename T>
T gaussian_sigma(T a, T b, T c, T dx, T dy) {
  // ½a·dx² + ½c·dy² + b·dx·dy, every product fused into the next sum (madd).
  return madd(T(0.5) * a * dx, dx, madd(T(0.5) * c * dy, dy, b * dx * dy));
}

// α = min(0.999, o·exp(−σ)) given o·exp(−σ); written as a value select (std::min
// returns a reference, which keeps GCC from vectorizing the pixel loops).
template <typename T>
T clamp_alpha(T raw) {
  return raw < T(kAlphaMax) ? raw : T(kAlphaMax);
}

// --- spherical harmonics (core/spherical_harmonics.hpp; degree ≤ 3 here) ------------
template <typename T>
void sh_basis(int degree, const Vec3<T>& d, T* Y) {
  desplat::sh_basis<T>(degree, d[0], d[1], d[2], Y);
}

// The color of one Gaussian before clamping: SH mode Σ_k c_k Y_k(dir) + 0.5 with
// dir = normalize(mean − cam_center); RGB mode the stored value.
template <typename T>
Vec3<T> evaluate_color(bool sh_mode, int degree, const T* coeffs, const Vec3<T>& mean, const Vec3<T>& cam_center) {
  if (!sh_mode) return Vec3<T>(coeffs[0], coeffs[1], coeffs[2]);
  using std::sqrt;
  Vec3<T> dir = mean - cam_center;
  const T n2 = dir.squaredNorm();
  dir = n2 > T(0) ? Vec3<T>(dir / sqrt(n2)) : Vec3<T>(T(0), T(0), T(1));
  T Y[16];
  sh_basis<T>(degree, dir, Y);
  Vec3<T> c(T(0.5), T(0.5), T(0.5));
  for (int k = 0; k < (degree + 1) * (degree + 1); ++k)
    for (int ch = 0; ch < 3; ++ch) c[ch] += coeffs[3 * k + ch] * Y[k];
  return c;
}

// Accumulates ∂L/∂coeffs and ∂L/∂mean (through dir) from ∂L/∂color (unclamped).
void evaluate_color_sh_vjp(int degree, const float* coeffs, const Vec3<float>& mean, const Vec3<float>& cam_center,
                           const Vec3<float>& d_color, float* d_coeffs, Vec3<float>& d_mean);

}  // namespace desplat::raster
