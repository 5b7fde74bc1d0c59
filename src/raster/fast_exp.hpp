// exp(x) for x ≤ 0 in float32, written so GCC/Clang vectorize it (std::exp does not
// vectorize without -ffast-math, which we do not use because it breaks NaN checks).
// Cody–Waite range reduction x = n·ln2 + r, |r| ≤ ln2/2, then p(r) = 1 + r·q(r) with q of
// degree 4, the least relative error to e^r on that interval (a Remez fit with p(0) = 1,
// so exp(0) = 1 exactly: scripts/fit_exp_polynomial.py). Relative error ≤ 1.7e-7 over every
// float in [−87, 0], 2.01 ulps at most (CUDA's __expf, which gsplat calls, is documented at
// 2 + ⌊|1.173·x|⌋ ulps). A degree-7 Taylor polynomial had 0.94 ulps at most but two more
// multiply-adds on every pixel's path to α (docs/METHOD.md §3). Inputs below −87
// return 0.
#pragma once

#include <bit>
#include <cstdint>

#include "raster/stage_math.hpp"

namespace desplat::raster {

inline float fast_exp_nonpositive(float x) {
  constexpr float kLog2e = 1.44269504088896341f;
  constexpr float kLn2Hi = 0.693359375f;
  constexpr float kLn2Lo = -2.12194440e-4f;
  const bool underflow = x < -87.0f;
  x = x < -87.0f ? -87.0f : x;
  // Round to nearest by adding and removing 1.5·2²³ (no libm call, so it vectorizes).
  constexpr float kRoundMagic = 12582912.0f;
  // Every product–sum is spelled as madd (stage_math.hpp): the forward and the backward
  // pass must get the same bits.
  const float n = madd(x, kLog2e, kRoundMagic) - kRoundMagic;
  const float r = madd(-n, kLn2Lo, madd(-n, kLn2Hi, x));
  float p = 8.290314728e-03f;
  p = madd(p, r, 4.189792930e-02f);
  p = madd(p, r, 1.666763619e-01f);
  p = madd(p, r, 4.999914953e-01f);
  p = madd(p, r, 9.999997072e-01f);
  p = madd(p, r, 1.0f);
  // Multiply by 2^n by building the float's exponent directly (n ≥ −126 here).
  const float two_n = std::bit_cast<float>(static_cast<int32_t>(n + 127.0f) << 23);
  return underflow ? 0.0f : p * two_n;
}

}  // namespace desplat::raster
