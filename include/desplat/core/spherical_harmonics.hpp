// Real spherical harmonics, the one basis every colour-by-direction in desplat uses: the static
// Gaussians' view-dependent colours (degree ≤ 3, gsplat's constants and ordering, so exported
// PLY files mean what other 3DGS tools read) and the background model's sky (degree ≤ 4).
//
// Band l holds 2l + 1 functions, m = −l … l in order; index k = l² + l + m. Each function is
// orthonormal over the unit sphere (∫ Y_i Y_j dΩ = δ_ij); the signs of bands 1–3 follow
// gsplat. The direction must be a unit vector (no normalization here).
#pragma once

namespace desplat {

constexpr int kMaxShDegree = 4;

// Y₀₀ = 1/(2√π), the constant band-0 function: a colour's DC coefficient c shows as
// 0.5 + kShBand0·c (the 3DGS convention every PLY reader shares).
inline constexpr double kShBand0 = 0.28209479177387814;
constexpr int sh_coefficients(int degree) { return (degree + 1) * (degree + 1); }

// Fills Y[0 .. sh_coefficients(min(degree, MaxDegree))) for the unit direction (x, y, z).
// MaxDegree (≤ kMaxShDegree) is the size Y was declared for: the Gaussians' colours stop at 3.
template <typename T, int MaxDegree = 3>
void sh_basis(int degree, T x, T y, T z, T* Y) {
  static_assert(MaxDegree >= 0 && MaxDegree <= kMaxShDegree);
  Y[0] = T(kShBand0);
  if (degree < 1) return;
  Y[1] = T(-0.48860251190292) * y;
  Y[2] = T(0.48860251190292) * z;
  Y[3] = T(-0.48860251190292) * x;
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z;
  Y[4] = T(1.092548430592079) * x * y;
  Y[5] = T(-1.092548430592079) * y * z;
  Y[6] = T(0.9461746957575601) * zz - T(0.3153915652525201);
  Y[7] = T(-1.092548430592079) * x * z;
  Y[8] = T(0.5462742152960749) * (xx - yy);
  if (degree < 3) return;
  Y[9] = T(-0.5900435899266435) * y * (T(3) * xx - yy);
  Y[10] = T(2.890611442640554) * x * y * z;
  Y[11] = (T(-2.285228997322329) * zz + T(0.4570457994644658)) * y;
  Y[12] = z * (T(1.865881662950577) * zz - T(1.119528997770346));
  Y[13] = (T(-2.285228997322329) * zz + T(0.4570457994644658)) * x;
  Y[14] = T(1.445305721320277) * z * (xx - yy);
  Y[15] = T(-0.5900435899266435) * x * (xx - T(3) * yy);
  if constexpr (MaxDegree < 4) return;
  if (degree < 4) return;
  // Band 4 (only the background uses it): the textbook real harmonics, e.g.
  // Y₄,₋₄ = (3/4)√(35/π)·xy(x² − y²), Y₄,₀ = (3/16)√(1/π)·(35z⁴ − 30z² + 3).
  const T seven_zz = T(7) * zz;
  Y[16] = T(2.5033429417967046) * x * y * (xx - yy);
  Y[17] = T(1.7701307697799304) * y * z * (T(3) * xx - yy);
  Y[18] = T(0.9461746957575601) * x * y * (seven_zz - T(1));
  Y[19] = T(0.6690465435572892) * y * z * (seven_zz - T(3));
  Y[20] = T(0.10578554691520431) * (zz * (T(35) * zz - T(30)) + T(3));
  Y[21] = T(0.6690465435572892) * x * z * (seven_zz - T(3));
  Y[22] = T(0.47308734787878004) * (xx - yy) * (seven_zz - T(1));
  Y[23] = T(1.7701307697799304) * x * z * (xx - T(3) * yy);
  Y[24] = T(0.6258357354491761) * (xx * (xx - T(3) * yy) - yy * (T(3) * xx - yy));
}

}  // namespace desplat
