// Hand-written vector–Jacobian products of the stages in stage_math.hpp.
// Each is checked against ceres::Jet derivatives of the templated forward function
// (tests/test_stage_math.cpp).
#include "raster/stage_math.hpp"

namespace desplat::raster {

Vec4<float> quat_vjp(const float* q_raw, const Mat3<float>& G) {
  float m = 0;
  for (int i = 0; i < 4; ++i) m = std::max(m, std::abs(q_raw[i]));
  if (!std::isfinite(m)) return Vec4<float>::Zero();
  const Vec4<float> q = normalize_quat<float>(q_raw);
  const float w = q[0], x = q[1], y = q[2], z = q[3];
  // ∂L/∂q̂ from the partial derivatives of each rotation-matrix entry.
  Vec4<float> dq;
  dq[0] = 2 * (-z * G(0, 1) + y * G(0, 2) + z * G(1, 0) - x * G(1, 2) - y * G(2, 0) + x * G(2, 1));
  dq[1] = 2 * (y * G(0, 1) + z * G(0, 2) + y * G(1, 0) - 2 * x * G(1, 1) - w * G(1, 2) + z * G(2, 0) + w * G(2, 1) -
               2 * x * G(2, 2));
  dq[2] = 2 * (-2 * y * G(0, 0) + x * G(0, 1) + w * G(0, 2) + x * G(1, 0) + z * G(1, 2) - w * G(2, 0) + z * G(2, 1) -
               2 * y * G(2, 2));
  dq[3] = 2 * (-2 * z * G(0, 0) - w * G(0, 1) + x * G(0, 2) + w * G(1, 0) - 2 * z * G(1, 1) + y * G(1, 2) +
               x * G(2, 0) + y * G(2, 1));
  // Through q̂ = q / |q|: (I − q̂ q̂ᵀ) ∂L/∂q̂ / |q|.
  float norm = 0;
  if (m > 0) {
    Vec4<float> u(q_raw[0] / m, q_raw[1] / m, q_raw[2] / m, q_raw[3] / m);
    norm = m * u.norm();
  }
  return (dq - q * q.dot(dq)) / std::max(norm, kMinQuatNorm);
}

void covariance_3d_vjp(const float* log_scale, const float* quat, const Mat3<float>& dSigma, float* d_log_scale,
                       float* d_quat) {
  const Mat3<float> R = rotation_from_unit_quat<float>(normalize_quat<float>(quat));
  const Vec3<float> S(std::exp(log_scale[0]), std::exp(log_scale[1]), std::exp(log_scale[2]));
  const Mat3<float> M = R * S.asDiagonal();
  // Σ = M Mᵀ  ⇒  ∂L/∂M = (G + Gᵀ) M.
  const Mat3<float> dM = (dSigma + dSigma.transpose()) * M;
  const Mat3<float> dR = dM * S.asDiagonal();
  for (int j = 0; j < 3; ++j) d_log_scale[j] += dM.col(j).dot(R.col(j)) * S[j];
  const Vec4<float> dq = quat_vjp(quat, dR);
  for (int i = 0; i < 4; ++i) d_quat[i] += dq[i];
}

void project_ewa_vjp(const Vec3<float>& p, const Mat3<float>& V, const PinholeIntrinsics& K,
                     const Vec2<float>& d_mean2d, const Mat2<float>& d_cov2d, float d_depth, Vec3<float>& d_p,
                     Mat3<float>& d_V) {
  const float x = p[0], y = p[1], z = p[2];
  const float rz = 1.0f / z, rz2 = rz * rz, rz3 = rz2 * rz;
  const FovLimits lim = fov_limits(K);
  const float lim_x_pos = float(lim.x_pos), lim_x_neg = float(lim.x_neg);
  const float lim_y_pos = float(lim.y_pos), lim_y_neg = float(lim.y_neg);
  const float txz = x * rz, tyz = y * rz;
  const bool x_free = txz <= lim_x_pos && txz >= -lim_x_neg;  // clamp inactive
  const bool y_free = tyz <= lim_y_pos && tyz >= -lim_y_neg;
  const float tx = z * std::min(lim_x_pos, std::max(-lim_x_neg, txz));
  const float ty = z * std::min(lim_y_pos, std::max(-lim_y_neg, tyz));
  Mat23<float> J;
  J << K.fx * rz, 0, -K.fx * tx * rz2, 0, K.fy * rz, -K.fy * ty * rz2;

  // cov2d = J V Jᵀ + eps·I.
  const Mat2<float> G = 0.5f * (d_cov2d + d_cov2d.transpose());
  d_V = J.transpose() * G * J;
  const Mat23<float> dJ = 2.0f * G * J * V;

  // mean2d = (fx·x/z + cx, fy·y/z + cy), depth = z.
  d_p = Vec3<float>(K.fx * rz * d_mean2d[0], K.fy * rz * d_mean2d[1],
                    -(K.fx * x * d_mean2d[0] + K.fy * y * d_mean2d[1]) * rz2 + d_depth);
  // J's entries as functions of p. J02 = −fx·tx/z² with tx = x (free) or z·limit
  // (clamped), so ∂J02/∂z is 2·fx·tx/z³ when free and fx·tx/z³ when clamped.
  d_p[2] += -K.fx * rz2 * dJ(0, 0) - K.fy * rz2 * dJ(1, 1);
  if (x_free) {
    d_p[0] += -K.fx * rz2 * dJ(0, 2);
    d_p[2] += 2.0f * K.fx * tx * rz3 * dJ(0, 2);
  } else {
    d_p[2] += K.fx * tx * rz3 * dJ(0, 2);
  }
  if (y_free) {
    d_p[1] += -K.fy * rz2 * dJ(1, 2);
    d_p[2] += 2.0f * K.fy * ty * rz3 * dJ(1, 2);
  } else {
    d_p[2] += K.fy * ty * rz3 * dJ(1, 2);
  }
}

Mat2<float> conic_vjp(const Vec3<float>& conic, const Vec3<float>& d_conic) {
  // Q = cov⁻¹, dQ = −Q d(cov) Q  ⇒  ∂L/∂cov = −Q G Q, with b's gradient split
  // between the two symmetric off-diagonal entries.
  Mat2<float> Q, G;
  Q << conic[0], conic[1], conic[1], conic[2];
  G << d_conic[0], 0.5f * d_conic[1], 0.5f * d_conic[1], d_conic[2];
  return -Q * G * Q;
}

namespace {
// ∇Y_k with respect to the unit direction, for k < (degree + 1)².
void sh_basis_gradient(int degree, const Vec3<float>& d, Vec3<float>* dY) {
  const float x = d[0], y = d[1], z = d[2];
  constexpr float C1 = 0.48860251190292f, A = 1.092548430592079f, B = 0.9461746957575601f, H = 0.5462742152960749f,
                  P = -0.5900435899266435f, Q = 2.890611442640554f, E = -2.285228997322329f, F = 0.4570457994644658f,
                  Gc = 1.865881662950577f, I = 1.119528997770346f, R = 1.445305721320277f;
  dY[0] = Vec3<float>::Zero();
  if (degree < 1) return;
  dY[1] = {0, -C1, 0};
  dY[2] = {0, 0, C1};
  dY[3] = {-C1, 0, 0};
  if (degree < 2) return;
  const float xx = x * x, yy = y * y, zz = z * z;
  dY[4] = {A * y, A * x, 0};
  dY[5] = {0, -A * z, -A * y};
  dY[6] = {0, 0, 2 * B * z};
  dY[7] = {-A * z, 0, -A * x};
  dY[8] = {2 * H * x, -2 * H * y, 0};
  if (degree < 3) return;
  dY[9] = {6 * P * x * y, P * (3 * xx - 3 * yy), 0};
  dY[10] = {Q * y * z, Q * x * z, Q * x * y};
  dY[11] = {0, E * zz + F, 2 * E * z * y};
  dY[12] = {0, 0, 3 * Gc * zz - I};
  dY[13] = {E * zz + F, 0, 2 * E * z * x};
  dY[14] = {2 * R * x * z, -2 * R * y * z, R * (xx - yy)};
  dY[15] = {P * (3 * xx - 3 * yy), -6 * P * x * y, 0};
}
}  // namespace

void evaluate_color_sh_vjp(int degree, const float* coeffs, const Vec3<float>& mean, const Vec3<float>& cam_center,
                           const Vec3<float>& d_color, float* d_coeffs, Vec3<float>& d_mean) {
  const Vec3<float> v = mean - cam_center;
  const float n = v.norm();
  const Vec3<float> dir = n > 0 ? Vec3<float>(v / n) : Vec3<float>(0, 0, 1);
  float Y[16];
  Vec3<float> dY[16];
  sh_basis<float>(degree, dir, Y);
  sh_basis_gradient(degree, dir, dY);
  Vec3<float> d_dir = Vec3<float>::Zero();
  const int K = (degree + 1) * (degree + 1);
  for (int k = 0; k < K; ++k) {
    float weighted = 0;  // Σ_ch c_k,ch · ∂L/∂color_ch
    for (int ch = 0; ch < 3; ++ch) {
      d_coeffs[3 * k + ch] += Y[k] * d_color[ch];
      weighted += coeffs[3 * k + ch] * d_color[ch];
    }
    d_dir += weighted * dY[k];
  }
  if (n > 0) d_mean += (d_dir - dir * dir.dot(d_dir)) / n;
}

}  // namespace desplat::raster
