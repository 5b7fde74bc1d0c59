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
      if (x + 1 < W) ASSERT_GT(std::abs(alpha[p] - alpha[p + 1]), 2e-3f);
      if (y + 1 < H) ASSERT_GT(std::abs(alpha[p] - alpha[p + W]), 2e-3f);
    }
  const float lambda = 0.7f, h = 1e-3f;
  std::vector<float> grad(alpha.size(), 0.0f), scratch(alpha.size(), 0.0f);
  mask_total_variation(alpha, W, H, lambda, grad);
  for (size_t p = 0; p < alpha.size(); ++p) {
    std::vector<float> up = alpha, down = alpha;
    up[p] += h, down[p] -= h;
    const double fd = (mask_total_variation(up, W, H, lambda, scratch) -
                       mask_total_variation(down, W, H, lambda, scratch)) /
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

}  // namespace
}  // namespace desplat
