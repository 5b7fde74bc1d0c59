// The distractor mask's total variation (train/mask_coherence.hpp): a hand-computed case,
// the user's mask, finite differences, and what it does to a hole in a mask.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "desplat/train/mask_coherence.hpp"
#include "support/expect.hpp"

namespace desplat {
namespace {

// 3 × 2 alpha:   0  1  0.5
//                0  1  1
// Horizontal pairs |0−1| + |1−0.5| + |0−1| + |1−1| = 2.5, vertical 0 + 0 + |0.5−1| = 0.5:
// sum 3, so λ = 0.6 over 6 pixels gives 0.3; each pair moves its pixels by ±λ/6 = ±0.1.
TEST(MaskTotalVariation, HandComputedValueAndGradient) {
  const std::vector<float> alpha{0, 1, 0.5f, 0, 1, 1};
  std::vector<float> grad(6, 0.0f);
  EXPECT_NEAR(mask_total_variation(alpha, 3, 2, 0.6f, grad), 0.3, 1e-7);
  const std::vector<float> expected{-0.1f, 0.2f, -0.2f, -0.1f, 0.1f, 0.1f};
  for (size_t p = 0; p < 6; ++p) EXPECT_NEAR(grad[p], expected[p], 1e-7) << "pixel " << p;
}

TEST(MaskTotalVariation, AddsToTheGradientItIsGiven) {
  const std::vector<float> alpha{0, 1};
  std::vector<float> grad{5.0f, -5.0f};
  mask_total_variation(alpha, 2, 1, 1.0f, grad);
  EXPECT_FLOAT_EQ(grad[0], 5.0f - 0.5f);
  EXPECT_FLOAT_EQ(grad[1], -5.0f + 0.5f);
}

// Pixel 2 ignored: its two pairs drop out and the mean runs over 5 pixels: 2 · 0.6 / 5.
TEST(MaskTotalVariation, IgnoredPixelsAreInNoPair) {
  const std::vector<float> alpha{0, 1, 0.5f, 0, 1, 1};
  const std::vector<float> keep{1, 1, 0, 1, 1, 1};
  std::vector<float> grad(6, 0.0f);
  EXPECT_NEAR(mask_total_variation(alpha, 3, 2, 0.6f, grad, keep), 0.24, 1e-7);
  const std::vector<float> expected{-0.12f, 0.12f, 0.0f, -0.12f, 0.12f, 0.0f};
  for (size_t p = 0; p < 6; ++p) EXPECT_NEAR(grad[p], expected[p], 1e-7) << "pixel " << p;
}

// A flat mask — a clean view with no distractor, or one covering everything — costs
// nothing and is pushed nowhere.
TEST(MaskTotalVariation, FlatMasksCostNothing) {
  for (float a : {0.0f, 0.37f, 1.0f}) {
    const std::vector<float> alpha(20, a);
    std::vector<float> grad(20, 0.0f);
    EXPECT_EQ(mask_total_variation(alpha, 5, 4, 1.0f, grad), 0.0);
    for (float g : grad) EXPECT_EQ(g, 0.0f);
  }
}

// Central differences in double of the value, away from ties (TV is piecewise linear).
TEST(MaskTotalVariation, MatchesFiniteDifferences) {
  const int W = 7, H = 5;
  std::vector<float> alpha(size_t(W) * H);
  for (size_t p = 0; p < alpha.size(); ++p) alpha[p] = float(std::fmod(0.618034 * double(p * p + 3 * p + 1), 1.0));
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {  // the check needs no adjacent pair within the step
      const size_t p = size_t(y) * W + x;
      if (x + 1 < W) {
        ASSERT_GT(std::abs(alpha[p] - alpha[p + 1]), 2e-3f);
      }
      if (y + 1 < H) {
        ASSERT_GT(std::abs(alpha[p] - alpha[p + W]), 2e-3f);
      }
    }
  const float lambda = 0.7f, h = 1e-3f;
  std::vector<float> grad(alpha.size(), 0.0f), scratch(alpha.size(), 0.0f);
  mask_total_variation(alpha, W, H, lambda, grad);
  for (size_t p = 0; p < alpha.size(); ++p) {
    std::vector<float> up = alpha, down = alpha;
    up[p] += h, down[p] -= h;
    const double fd =
        (mask_total_variation(up, W, H, lambda, scratch) - mask_total_variation(down, W, H, lambda, scratch)) /
        (double(up[p]) - double(down[p]));
    EXPECT_NEAR(grad[p], fd, 1e-5) << "pixel " << p;
  }
}

// Gradient descent on TV fills a one-pixel hole in an opaque square: the hole's four
// neighbours are all at 1, so the prior pushes it up. Only the hole moves here: it stands for
// a pixel where the object matches the background, so the photometric loss has no say; the
// square's own pixels are what the photometric loss holds in training.
TEST(MaskTotalVariation, FillsAHoleInsideAnObject) {
  const int W = 7, H = 7;
  std::vector<float> alpha(size_t(W) * H, 0.0f);
  for (int y = 1; y < 6; ++y)
    for (int x = 1; x < 6; ++x) alpha[size_t(y) * W + x] = 1.0f;
  const size_t hole = 3 * W + 3;
  alpha[hole] = 0.0f;
  std::vector<float> grad(alpha.size());
  for (int it = 0; it < 100; ++it) {
    std::fill(grad.begin(), grad.end(), 0.0f);
    mask_total_variation(alpha, W, H, 1.0f, grad);
    alpha[hole] = std::clamp(alpha[hole] - 0.5f * grad[hole], 0.0f, 1.0f);
  }
  EXPECT_GT(alpha[hole], 0.99f);
}

TEST(MaskTotalVariation, WrongSizesAreOneClearError) {
  std::vector<float> alpha(6), grad(5);
  const auto message = testing::error_of<std::invalid_argument>([&] { mask_total_variation(alpha, 3, 2, 1.0f, grad); });
  EXPECT_CONTAINS(message, "mask_total_variation");
}

// Two pixels, photo I = (0.2, 0.4, 0.6) and (1, 1, 1).
// Pixel 0: A_d = 0.5, C_d = (0.1, 0.3, 0.2) → C_d − A_d·I = (0, +0.1, −0.1), sum 0.2.
// Pixel 1: A_d = 0.25, C_d = (0.5, 0, 0.25) → (+0.25, −0.25, 0), sum 0.5.
// λ = 0.6: value 0.6 · 0.7 / (3 · 2) = 0.07; each nonzero term moves its colour by
// ±λ/6 = ±0.1 and the alpha by ∓0.1·I_c.
TEST(OccluderColourPrior, HandComputedValueAndGradient) {
  const std::vector<float> color{0.1f, 0.3f, 0.2f, 0.5f, 0.0f, 0.25f}, alpha{0.5f, 0.25f};
  const std::vector<float> photo{0.2f, 0.4f, 0.6f, 1.0f, 1.0f, 1.0f};
  std::vector<float> d_color(6, 0.0f), d_alpha(2, 0.0f);
  EXPECT_NEAR(occluder_colour_prior({color, alpha}, photo, 0.6f, d_color, d_alpha), 0.07, 1e-7);
  const std::vector<float> expected_color{0.0f, 0.1f, -0.1f, 0.1f, -0.1f, 0.0f};
  for (size_t i = 0; i < 6; ++i) EXPECT_NEAR(d_color[i], expected_color[i], 1e-7) << "entry " << i;
  EXPECT_NEAR(d_alpha[0], -0.1f * 0.4f + 0.1f * 0.6f, 1e-7);
  EXPECT_NEAR(d_alpha[1], -0.1f * 1.0f + 0.1f * 1.0f, 1e-7);
}

// Where the composite C_d + (1 − A_d)·s fits the photo, the value is (1 − A_d)·|I − s|:
// a faint distractor of an extreme colour pays for the static layer's whole miss, an opaque
// one of the photo's colour nothing. Checked against that closed form for several A_d.
TEST(OccluderColourPrior, OnAFittedPixelItIsTheUnclaimedShareOfTheStaticMiss) {
  const std::vector<float> photo{0.7f, 0.5f, 0.3f}, statics{0.4f, 0.45f, 0.35f};
  double miss = 0;
  for (int c = 0; c < 3; ++c) miss += std::abs(double(photo[c]) - statics[c]) / 3.0;
  for (float a : {0.1f, 0.3f, 0.6f, 1.0f}) {
    std::vector<float> color(3), alpha{a}, d_color(3, 0.0f), d_alpha(1, 0.0f);
    for (int c = 0; c < 3; ++c) color[c] = photo[c] - (1.0f - a) * statics[c];  // the composite fits
    EXPECT_NEAR(occluder_colour_prior({color, alpha}, photo, 1.0f, d_color, d_alpha), (1.0 - a) * miss, 1e-6)
        << "A_d = " << a;
  }
}

// Central differences in double of the value (piecewise linear; no term within the step of 0).
TEST(OccluderColourPrior, MatchesFiniteDifferences) {
  const size_t P = 12;
  std::vector<float> color(3 * P), alpha(P), photo(3 * P);
  for (size_t p = 0; p < P; ++p) {
    alpha[p] = float(std::fmod(0.618034 * double(p * p + 1), 1.0));
    for (int c = 0; c < 3; ++c) {
      photo[3 * p + c] = float(std::fmod(0.414214 * double(7 * p + c + 2), 1.0));
      color[3 * p + c] = float(std::fmod(0.732051 * double(5 * p + 3 * c + 1), 1.0)) * alpha[p];
      // Keep every term away from its kink: the steps below move it by at most 1e-3.
      if (std::abs(color[3 * p + c] - alpha[p] * photo[3 * p + c]) < 0.01f) color[3 * p + c] += 0.02f;
      ASSERT_GT(std::abs(color[3 * p + c] - alpha[p] * photo[3 * p + c]), 3e-3f);
    }
  }
  const std::vector<float> keep{1, 1, 0, 1, 1, 1, 1, 0, 1, 1, 1, 1};
  const float lambda = 0.7f, h = 1e-3f;
  std::vector<float> d_color(3 * P, 0.0f), d_alpha(P, 0.0f), sc(3 * P), sa(P);
  occluder_colour_prior({color, alpha}, photo, lambda, d_color, d_alpha, keep);
  auto value = [&](const std::vector<float>& c, const std::vector<float>& a) {
    return occluder_colour_prior({c, a}, photo, lambda, sc, sa, keep);
  };
  for (size_t i = 0; i < 3 * P; ++i) {
    std::vector<float> up = color, down = color;
    up[i] += h, down[i] -= h;
    EXPECT_NEAR(d_color[i], (value(up, alpha) - value(down, alpha)) / (double(up[i]) - double(down[i])), 1e-5)
        << "colour " << i;
  }
  for (size_t p = 0; p < P; ++p) {
    std::vector<float> up = alpha, down = alpha;
    up[p] += h, down[p] -= h;
    EXPECT_NEAR(d_alpha[p], (value(color, up) - value(color, down)) / (double(up[p]) - double(down[p])), 1e-5)
        << "alpha " << p;
  }
  EXPECT_EQ(d_alpha[2], 0.0f);  // ignored pixels get nothing
  EXPECT_EQ(d_color[21], 0.0f);
}

TEST(OccluderColourPrior, WrongSizesAreOneClearError) {
  std::vector<float> color(6), alpha(2), photo(5), dc(6), da(2);
  const auto message = testing::error_of<std::invalid_argument>([&] {
    occluder_colour_prior({color, alpha}, photo, 1.0f, dc, da);
  });
  EXPECT_CONTAINS(message, "occluder_colour_prior");
}

}  // namespace
}  // namespace desplat
