// exp(x) for x ≤ 0 in float32, written so GCC/Clang vectorize it (std::exp does not
// vectorize without -ffast-math, which we do not use because it breaks NaN checks).
// Cody–Waite range reduction x = n·ln2 + r, |r| ≤ ln2/2, then a degree-7 Taylor
// polynomial: relative error ≤ 2e-7 (checked against std::exp in the tests), about
// what gsplat's CUDA __expf gives. Inputs below −87 return 0.
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
  float p = 1.0f / 5040.0f;
  p = madd(p, r, 1.0f / 720.0f);
  p = madd(p, r, 1.0f / 120.0f);
  p = madd(p, r, 1.0f / 24.0f);
  p = madd(p, r, 1.0f / 6.0f);
  p = madd(p, r, 0.5f);
  p = madd(p, r, 1.0f);
  p = madd(p, r, 1.0f);
  // Multiply by 2^n by building the float's exponent directly (n ≥ −126 here).
  const float two_n = std::bit_cast<float>(static_cast<int32_t>(n + 127.0f) << 23);
  return underflow ? 0.0f : p * two_n;
}

}  // namespace desplat::raster
