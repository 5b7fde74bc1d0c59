// The per-Gaussian geometry of the projection (docs/METHOD.md §2–3) for kLanes Gaussians at
// once, in structure-of-arrays form: each stage is one branch-free loop over the lanes, which
// the compiler turns into vector code (one Gaussian per lane). The same math as the scalar
// templates in stage_math.hpp (normalize_quat, rotation_from_unit_quat, covariance_3d,
// project_ewa, conic_from_cov2d), which stay the reference the tests compare these with; the
// sums are written out entry by entry, so the last bits of a result may differ from the
// scalar templates' (float rounding only).
#pragma once

#include <cmath>
#include <cstdint>

#include "raster/stage_math.hpp"

namespace desplat::raster {

constexpr int kLanes = 16;

// One camera, as the lane loops read it. Units: pixels for the intrinsics, world units for t.
struct LaneCamera {
  float W[9];  // world → camera rotation, row-major
  float t[3];  // world → camera translation
  float fx, fy, cx, cy, eps2d;
  float lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;  // project_ewa's clamp of x/z and y/z
  float near_plane, far_plane, width, height;

  LaneCamera(const float* R_cw_row_major, const float* t_cw, const PinholeIntrinsics& K, float eps, float near,
             float far) {
    for (int k = 0; k < 9; ++k) W[k] = R_cw_row_major[k];
    for (int k = 0; k < 3; ++k) t[k] = t_cw[k];
    fx = K.fx, fy = K.fy, cx = K.cx, cy = K.cy, eps2d = eps;
    const FovLimits lim = fov_limits(K);
    lim_x_pos = float(lim.x_pos), lim_x_neg = float(lim.x_neg);
    lim_y_pos = float(lim.y_pos), lim_y_neg = float(lim.y_neg);
    near_plane = near, far_plane = far, width = float(K.width), height = float(K.height);
  }
};

// A block's inputs: world-space means, scales (exp of the log-scales) and raw quaternions
// (w, x, y, z). Lanes past the block's end hold a mean with z = NaN (never visible).
struct LaneGaussians {
  float mean[3][kLanes];
  float scale[3][kLanes];
  float quat[4][kLanes];
};

// The rotation and the 3D covariance's factor M = R·diag(scale), per lane.
struct LaneRotation {
  float q[4][kLanes];  // the unit quaternion (w, x, y, z)
  float R[9][kLanes];  // row-major
  float M[9][kLanes];  // row-major
};

// Unit quaternion → rotation (normalize_quat, rotation_from_unit_quat): the quaternion is
// divided by its largest component first, and a zero or non-finite one maps to the identity.
inline void rotation_lanes(const LaneGaussians& g, LaneRotation& r) {
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {
    float m = std::abs(g.quat[0][l]);
    for (int k = 1; k < 4; ++k) {
      const float a = std::abs(g.quat[k][l]);
      m = m < a ? a : m;  // std::max's rule: a NaN component leaves m as it is
    }
    const bool ok = m > 0.0f && m < INFINITY;
    const float safe_m = ok ? m : 1.0f;
    float u[4];
    for (int k = 0; k < 4; ++k) u[k] = g.quat[k][l] / safe_m;
    const float norm = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + u[3] * u[3]);
    const float w = ok ? u[0] / norm : 1.0f, x = ok ? u[1] / norm : 0.0f;
    const float y = ok ? u[2] / norm : 0.0f, z = ok ? u[3] / norm : 0.0f;
    r.q[0][l] = w, r.q[1][l] = x, r.q[2][l] = y, r.q[3][l] = z;
    const float R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                        2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) {
        r.R[3 * i + k][l] = R[3 * i + k];
        r.M[3 * i + k][l] = R[3 * i + k] * g.scale[k][l];
      }
  }
}

// The camera-space covariance V = W Σ Wᵀ with Σ = M Mᵀ: its six entries
// (00, 01, 02, 11, 12, 22) per lane.
inline void camera_covariance_lanes(const LaneCamera& c, const LaneRotation& r, float (&V)[6][kLanes]) {
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {
    // WM = W·M, then V = (WM)(WM)ᵀ.
    float WM[9];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k)
        WM[3 * i + k] = c.W[3 * i] * r.M[k][l] + c.W[3 * i + 1] * r.M[3 + k][l] + c.W[3 * i + 2] * r.M[6 + k][l];
    auto dot = [&](int i, int j) {
      return WM[3 * i] * WM[3 * j] + WM[3 * i + 1] * WM[3 * j + 1] + WM[3 * i + 2] * WM[3 * j + 2];
    };
    V[0][l] = dot(0, 0), V[1][l] = dot(0, 1), V[2][l] = dot(0, 2);
    V[3][l] = dot(1, 1), V[4][l] = dot(1, 2), V[5][l] = dot(2, 2);
  }
}

// A block's rotation and camera-space covariance: what the projection and its backward share.
struct LaneGeometry {
  LaneRotation rot;
  float V[6][kLanes];
};
inline void geometry_lanes(const LaneCamera& c, const LaneGaussians& g, LaneGeometry& out) {
  rotation_lanes(g, out.rot);
  camera_covariance_lanes(c, out.rot, out.V);
}

// What the projection of a block yields, per lane.
struct LaneProjection {
  float p[3][kLanes];       // camera-space mean
  float mean2d[2][kLanes];  // [px]
  float cov2d[3][kLanes];   // 00, 01, 11, with eps2d [px²]
  float conic[3][kLanes];   // a, b, c of cov2d⁻¹
  float radius[2][kLanes];  // ⌈3.33σ⌉ per axis, capped at kMaxRadius [px]
  int32_t visible[kLanes];  // in depth range, invertible, finite, box overlaps the image
};

inline bool lane_finite(float x) { return std::abs(x) < INFINITY; }

// min(kMaxRadius, ⌈v⌉) for v ≥ 0 or NaN (NaN gives kMaxRadius, as std::min does). GCC
// vectorizes neither std::ceil nor a float→int conversion in these loops, so: round to the
// nearest integer by adding and removing 1.5·2²³ (exact below 2²²), then step up if that
// fell below v.
inline float capped_ceil(float v) {
  constexpr float kRoundMagic = 12582912.0f;
  const float capped = v < kMaxRadius ? v : kMaxRadius;
  const float nearest = (capped + kRoundMagic) - kRoundMagic;
  return nearest < capped ? nearest + 1.0f : nearest;
}

// The EWA projection of a block (project_ewa, conic_from_cov2d and preprocess's culling).
inline void project_lanes(const LaneCamera& c, const LaneGaussians& g, const float (&V)[6][kLanes], LaneProjection& o) {
  // The camera's numbers as locals and the visibility test without short-circuits (&, not
  // &&): conditional loads inside the loop keep the compiler from vectorizing it.
  const float W0 = c.W[0], W1 = c.W[1], W2 = c.W[2], W3 = c.W[3], W4 = c.W[4], W5 = c.W[5];
  const float W6 = c.W[6], W7 = c.W[7], W8 = c.W[8], t0 = c.t[0], t1 = c.t[1], t2 = c.t[2];
  const float fx = c.fx, fy = c.fy, cx = c.cx, cy = c.cy, eps2d = c.eps2d;
  const float lxp = c.lim_x_pos, lxn = c.lim_x_neg, lyp = c.lim_y_pos, lyn = c.lim_y_neg;
  const float near = c.near_plane, far = c.far_plane, width = c.width, height = c.height;
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {
    const float gx = g.mean[0][l], gy = g.mean[1][l], gz = g.mean[2][l];
    const float x = W0 * gx + W1 * gy + W2 * gz + t0;
    const float y = W3 * gx + W4 * gy + W5 * gz + t1;
    const float z = W6 * gx + W7 * gy + W8 * gz + t2;
    const bool in_depth = (z > near) & (z < far);  // also rejects NaN
    const float rz = 1.0f / z;
    const float xz = x * rz, yz = y * rz;
    const float tx = z * (xz < -lxn ? -lxn : (xz > lxp ? lxp : xz));
    const float ty = z * (yz < -lyn ? -lyn : (yz > lyp ? lyp : yz));
    // J = [[j00, 0, j02], [0, j11, j12]]; cov2d = J V Jᵀ + eps·I.
    const float j00 = fx * rz, j02 = -fx * tx * rz * rz;
    const float j11 = fy * rz, j12 = -fy * ty * rz * rz;
    const float V00 = V[0][l], V01 = V[1][l], V02 = V[2][l], V11 = V[3][l], V12 = V[4][l], V22 = V[5][l];
    const float a0 = j00 * V00 + j02 * V02, a1 = j00 * V01 + j02 * V12, a2 = j00 * V02 + j02 * V22;
    const float b1 = j11 * V11 + j12 * V12, b2 = j11 * V12 + j12 * V22;
    const float s00 = a0 * j00 + a2 * j02 + eps2d;
    const float s01 = a1 * j11 + a2 * j12;
    const float s11 = b1 * j11 + b2 * j12 + eps2d;
    const float det = s00 * s11 - s01 * s01;
    const float inv = 1.0f / det;
    const float ca = s11 * inv, cb = -s01 * inv, cc = s00 * inv;
    const float mx = fx * x * rz + cx, my = fy * y * rz + cy;
    const float ex = kExtentSigmas * std::sqrt(s00), ey = kExtentSigmas * std::sqrt(s11);
    const float rx = capped_ceil(ex), ry = capped_ceil(ey);
    // rx > 0 exactly when !(ex ≤ 0) (NaN gives kMaxRadius); tested on ex, ey, which GCC vectorizes.
    const bool positive = !(ex <= 0.0f) & !(ey <= 0.0f);
    const bool on_screen = (mx + rx > 0) & (mx - rx < width) & (my + ry > 0) & (my - ry < height);
    const bool finite = lane_finite(ca) & lane_finite(cb) & lane_finite(cc) & lane_finite(mx) & lane_finite(my);
    o.visible[l] = in_depth & (det > 0) & finite & positive & on_screen;
    o.p[0][l] = x, o.p[1][l] = y, o.p[2][l] = z;
    o.mean2d[0][l] = mx, o.mean2d[1][l] = my;
    o.cov2d[0][l] = s00, o.cov2d[1][l] = s01, o.cov2d[2][l] = s11;
    o.conic[0][l] = ca, o.conic[1][l] = cb, o.conic[2][l] = cc;
    o.radius[0][l] = rx, o.radius[1][l] = ry;
  }
}

// The backward of the geometry for a block: from ∂L/∂mean2d, ∂L/∂conic and ∂L/∂depth to
// ∂L/∂mean (through the projection only), ∂L/∂log_scale and ∂L/∂quat (raw). The chain of
// conic_vjp, project_ewa_vjp, the camera rotation and covariance_3d_vjp / quat_vjp
// (stage_math.cpp), lane by lane.
struct LaneGradientsIn {
  float conic[3][kLanes];
  float d_mean2d[2][kLanes];
  float d_conic[3][kLanes];
  float d_depth[kLanes];
};
struct LaneGradientsOut {
  float d_mean[3][kLanes];
  float d_log_scale[3][kLanes];
  float d_quat[4][kLanes];
};

inline void backward_lanes(const LaneCamera& c, const LaneGaussians& g, const LaneRotation& r,
                           const float (&V)[6][kLanes], const LaneGradientsIn& in, LaneGradientsOut& o) {
  const float W0 = c.W[0], W1 = c.W[1], W2 = c.W[2], W3 = c.W[3], W4 = c.W[4], W5 = c.W[5];
  const float W6 = c.W[6], W7 = c.W[7], W8 = c.W[8], t0 = c.t[0], t1 = c.t[1], t2 = c.t[2];
  const float fx = c.fx, fy = c.fy;
  const float lxp = c.lim_x_pos, lxn = c.lim_x_neg, lyp = c.lim_y_pos, lyn = c.lim_y_neg;
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {
    // conic_vjp: ∂L/∂cov = −Q G Q with Q the conic and G its gradient (b's split in two).
    const float qa = in.conic[0][l], qb = in.conic[1][l], qc = in.conic[2][l];
    const float ga = in.d_conic[0][l], gb = 0.5f * in.d_conic[1][l], gc = in.d_conic[2][l];
    const float h00 = ga * qa + gb * qb, h01 = ga * qb + gb * qc;  // H = G Q
    const float h10 = gb * qa + gc * qb, h11 = gb * qb + gc * qc;
    const float G00 = -(qa * h00 + qb * h10), G01 = -(qa * h01 + qb * h11);
    const float G10 = -(qb * h00 + qc * h10), G11 = -(qb * h01 + qc * h11);
    // project_ewa_vjp takes the symmetric part.
    const float S00 = G00, S11 = G11, S01 = 0.5f * (G01 + G10);

    const float gx = g.mean[0][l], gy = g.mean[1][l], gz = g.mean[2][l];
    const float x = W0 * gx + W1 * gy + W2 * gz + t0;
    const float y = W3 * gx + W4 * gy + W5 * gz + t1;
    const float z = W6 * gx + W7 * gy + W8 * gz + t2;
    const float rz = 1.0f / z, rz2 = rz * rz, rz3 = rz2 * rz;
    const float txz = x * rz, tyz = y * rz;
    const bool x_free = (txz <= lxp) & (txz >= -lxn);
    const bool y_free = (tyz <= lyp) & (tyz >= -lyn);
    const float tx = z * (txz < -lxn ? -lxn : (txz > lxp ? lxp : txz));
    const float ty = z * (tyz < -lyn ? -lyn : (tyz > lyp ? lyp : tyz));
    const float j00 = fx * rz, j02 = -fx * tx * rz2, j11 = fy * rz, j12 = -fy * ty * rz2;
    // d_V = Jᵀ S J (symmetric), with J = [[j00, 0, j02], [0, j11, j12]].
    const float dV00 = j00 * S00 * j00, dV01 = j00 * S01 * j11;
    const float dV02 = j00 * (S00 * j02 + S01 * j12), dV11 = j11 * S11 * j11;
    const float dV12 = j11 * (S01 * j02 + S11 * j12);
    const float dV22 = j02 * (S00 * j02 + S01 * j12) + j12 * (S01 * j02 + S11 * j12);
    // dJ = 2 S J V; only its entries (0,0), (0,2), (1,1), (1,2) are used.
    const float V00 = V[0][l], V01 = V[1][l], V02 = V[2][l], V11 = V[3][l], V12 = V[4][l], V22 = V[5][l];
    const float JV00 = j00 * V00 + j02 * V02, JV01 = j00 * V01 + j02 * V12, JV02 = j00 * V02 + j02 * V22;
    const float JV10 = j11 * V01 + j12 * V02, JV11 = j11 * V11 + j12 * V12, JV12 = j11 * V12 + j12 * V22;
    const float dJ00 = 2.0f * (S00 * JV00 + S01 * JV10), dJ02 = 2.0f * (S00 * JV02 + S01 * JV12);
    const float dJ11 = 2.0f * (S01 * JV01 + S11 * JV11), dJ12 = 2.0f * (S01 * JV02 + S11 * JV12);
    const float dmx = in.d_mean2d[0][l], dmy = in.d_mean2d[1][l];
    float dpx = fx * rz * dmx, dpy = fy * rz * dmy;
    float dpz = -(fx * x * dmx + fy * y * dmy) * rz2 + in.d_depth[l];
    dpz += -fx * rz2 * dJ00 - fy * rz2 * dJ11;
    dpx += x_free ? -fx * rz2 * dJ02 : 0.0f;
    dpz += (x_free ? 2.0f : 1.0f) * fx * tx * rz3 * dJ02;
    dpy += y_free ? -fy * rz2 * dJ12 : 0.0f;
    dpz += (y_free ? 2.0f : 1.0f) * fy * ty * rz3 * dJ12;
    // World frame: d_mean = Wᵀ d_p, dΣ = Wᵀ dV W.
    o.d_mean[0][l] = W0 * dpx + W3 * dpy + W6 * dpz;
    o.d_mean[1][l] = W1 * dpx + W4 * dpy + W7 * dpz;
    o.d_mean[2][l] = W2 * dpx + W5 * dpy + W8 * dpz;
    const float dV[9] = {dV00, dV01, dV02, dV01, dV11, dV12, dV02, dV12, dV22};
    const float Wm[9] = {W0, W1, W2, W3, W4, W5, W6, W7, W8};
    float dVW[9];  // dV W
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k)
        dVW[3 * i + k] = dV[3 * i] * Wm[k] + dV[3 * i + 1] * Wm[3 + k] + dV[3 * i + 2] * Wm[6 + k];
    float dS[9];  // Wᵀ (dV W), symmetric
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) dS[3 * i + k] = Wm[i] * dVW[k] + Wm[3 + i] * dVW[3 + k] + Wm[6 + i] * dVW[6 + k];
    // covariance_3d_vjp: ∂L/∂M = (dΣ + dΣᵀ) M, ∂L/∂R = ∂L/∂M · diag(S).
    float dR[9];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) {
        float dM = 0.0f;
        for (int m = 0; m < 3; ++m) dM += (dS[3 * i + m] + dS[3 * m + i]) * r.M[3 * m + k][l];
        dR[3 * i + k] = dM * g.scale[k][l];
      }
    for (int k = 0; k < 3; ++k) {
      // Σ_i ∂L/∂M_ik R_ik S_k = Σ_i ∂L/∂R_ik R_ik.
      o.d_log_scale[k][l] = dR[k] * r.R[k][l] + dR[3 + k] * r.R[3 + k][l] + dR[6 + k] * r.R[6 + k][l];
    }
    // quat_vjp: through the unit quaternion q̂ = q/|q| of the raw one.
    float m = 0.0f;
    for (int k = 0; k < 4; ++k) {
      const float a = std::abs(g.quat[k][l]);
      m = m < a ? a : m;
    }
    const bool finite_m = m < INFINITY;
    const float w = r.q[0][l], qx = r.q[1][l], qy = r.q[2][l], qz = r.q[3][l];
    const float dq0 = 2 * (-qz * dR[1] + qy * dR[2] + qz * dR[3] - qx * dR[5] - qy * dR[6] + qx * dR[7]);
    const float dq1 = 2 * (qy * dR[1] + qz * dR[2] + qy * dR[3] - 2 * qx * dR[4] - w * dR[5] + qz * dR[6] + w * dR[7] -
                           2 * qx * dR[8]);
    const float dq2 = 2 * (-2 * qy * dR[0] + qx * dR[1] + w * dR[2] + qx * dR[3] + qz * dR[5] - w * dR[6] + qz * dR[7] -
                           2 * qy * dR[8]);
    const float dq3 = 2 * (-2 * qz * dR[0] - w * dR[1] + qx * dR[2] + w * dR[3] - 2 * qz * dR[4] + qy * dR[5] +
                           qx * dR[6] + qy * dR[7]);
    // |q| = m·|q/m| (m > 0), never below kMinQuatNorm; an infinite component: no gradient.
    const float safe_m = m > 0.0f ? m : 1.0f;
    float v2 = 0.0f;
    for (int k = 0; k < 4; ++k) v2 += (g.quat[k][l] / safe_m) * (g.quat[k][l] / safe_m);
    const float norm = m > 0.0f ? m * std::sqrt(v2) : 0.0f;
    const float denom = norm < kMinQuatNorm ? kMinQuatNorm : norm;  // std::max(norm, kMinQuatNorm)
    const float proj = w * dq0 + qx * dq1 + qy * dq2 + qz * dq3;
    o.d_quat[0][l] = finite_m ? (dq0 - w * proj) / denom : 0.0f;
    o.d_quat[1][l] = finite_m ? (dq1 - qx * proj) / denom : 0.0f;
    o.d_quat[2][l] = finite_m ? (dq2 - qy * proj) / denom : 0.0f;
    o.d_quat[3][l] = finite_m ? (dq3 - qz * proj) / denom : 0.0f;
  }
}

}  // namespace desplat::raster
