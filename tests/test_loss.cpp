// The photometric loss against a brute-force double-precision implementation written
// directly from the definition (explicit 2D 11×11 windows, no separable filtering),
// and its gradient against central finite differences of that reference.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "desplat/train/loss.hpp"

namespace desplat {
namespace {

// With `keep`, only window positions whose center pixel is kept count.
double reference_ssim(const std::vector<double>& x, const std::vector<double>& y, int w, int h,
                      const std::vector<float>* keep = nullptr) {
  double g1[11], sum = 0;
  for (int i = 0; i < 11; ++i) sum += g1[i] = std::exp(-0.5 * (i - 5) * (i - 5) / (1.5 * 1.5));
  const double c1 = 1e-4, c2 = 9e-4;
  double total = 0;
  int count = 0;
  for (int ch = 0; ch < 3; ++ch)
    for (int oy = 0; oy + 11 <= h; ++oy)
      for (int ox = 0; ox + 11 <= w; ++ox) {
        if (keep && (*keep)[(oy + 5) * w + ox + 5] == 0) continue;
        double mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            const double wgt = g1[i] * g1[j] / (sum * sum);
            const double a = x[3 * ((oy + i) * w + ox + j) + ch], b = y[3 * ((oy + i) * w + ox + j) + ch];
            mx += wgt * a, my += wgt * b, xx += wgt * a * a, yy += wgt * b * b, xy += wgt * a * b;
          }
        const double sx = xx - mx * mx, sy = yy - my * my, sxy = xy - mx * my;
        total += ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sx + sy + c2));
        ++count;
      }
  return total / count;
}

double reference_loss(const std::vector<double>& x, const std::vector<double>& y, int w, int h, double lambda) {
  double l1 = 0;
  for (size_t i = 0; i < x.size(); ++i) l1 += std::abs(x[i] - y[i]);
  return (1 - lambda) * l1 / x.size() + lambda * (1 - reference_ssim(x, y, w, h));
}

struct Images {
  std::vector<float> render, target;
};

// Smooth random images plus noise, with |render − target| ≥ 2e-3 everywhere so the
// L1 kink is farther than the finite-difference step.
Images random_images(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  Images im{std::vector<float>(size_t(w) * h * 3), std::vector<float>(size_t(w) * h * 3)};
  for (size_t i = 0; i < im.render.size(); ++i) {
    const float base = 0.5f + 0.3f * std::sin(0.3f * float(i % (3 * w)) + 0.2f * float(i / (3 * w)));
    im.target[i] = base + 0.1f * u(rng);
    float d = 0.15f * (u(rng) - 0.5f);
    if (std::abs(d) < 2e-3f) d = d < 0 ? -2e-3f : 2e-3f;
    im.render[i] = im.target[i] + d;
  }
  return im;
}

TEST(Loss, ValueMatchesDirectDefinition) {
  for (auto [w, h] : {std::pair{11, 11}, std::pair{23, 17}, std::pair{40, 31}}) {
    const Images im = random_images(w, h, 5);
    const std::vector<double> x(im.render.begin(), im.render.end()), y(im.target.begin(), im.target.end());
    const PhotometricLoss got = photometric_loss(im.render, im.target, w, h, 0.2f, {});
    // Float32 filtering of O(1) values: the statistics carry ~1e-7 relative error,
    // amplified by the variance terms' cancellation; 2e-5 leaves a 10x margin.
    EXPECT_NEAR(got.ssim, reference_ssim(x, y, w, h), 2e-5) << w << "x" << h;
    EXPECT_NEAR(got.loss, reference_loss(x, y, w, h, 0.2), 2e-5) << w << "x" << h;
    EXPECT_NEAR(ssim(im.render, im.target, w, h), got.ssim, 1e-12);
  }
}

TEST(Loss, IdenticalImagesHaveSsimOneAndInfinitePsnr) {
  const Images im = random_images(20, 15, 1);
  EXPECT_NEAR(ssim(im.target, im.target, 20, 15), 1.0, 1e-5);
  EXPECT_TRUE(std::isinf(psnr(im.target, im.target)));
  std::vector<float> shifted = im.target;
  for (float& v : shifted) v += 0.1f;  // MSE 0.01 → 20 dB
  EXPECT_NEAR(psnr(shifted, im.target), 20.0, 1e-4);
}

// PSNR reads RGB images: a buffer that is not 3 floats per pixel is an error, not a
// PSNR over a silently dropped tail.
TEST(Loss, PsnrOfImagesThatAreNotRgbIsAnError) {
  const std::vector<float> a(10, 0.5f), b(10, 0.25f);
  EXPECT_THROW(psnr(a, b), std::invalid_argument);
  EXPECT_NEAR(psnr(std::span<const float>(a).first(9), std::span<const float>(b).first(9)), -10.0 * std::log10(0.0625),
              1e-9);
}

TEST(Loss, GradientMatchesFiniteDifferences) {
  const int w = 17, h = 14;
  const Images im = random_images(w, h, 9);
  std::vector<float> grad(im.render.size());
  photometric_loss(im.render, im.target, w, h, 0.2f, grad);
  std::vector<double> x(im.render.begin(), im.render.end());
  const std::vector<double> y(im.target.begin(), im.target.end());
  // Double-precision central differences with h = 1e-4: truncation O(h²·f''') ≈ 1e-9,
  // round-off ≈ 1e-16/1e-4; both far below the float gradient's own error (~1e-7 of
  // the largest entry), so 1e-3 relative to the largest entry catches any wrong term.
  double scale = 0;
  std::vector<double> numeric(x.size());
  for (size_t i = 0; i < x.size(); ++i) {
    const double keep = x[i];
    x[i] = keep + 1e-4;
    const double lp = reference_loss(x, y, w, h, 0.2);
    x[i] = keep - 1e-4;
    const double lm = reference_loss(x, y, w, h, 0.2);
    x[i] = keep;
    numeric[i] = (lp - lm) / 2e-4;
    scale = std::max(scale, std::abs(numeric[i]));
  }
  for (size_t i = 0; i < x.size(); ++i) EXPECT_NEAR(grad[i], numeric[i], 1e-3 * scale) << i;
}

TEST(Loss, RejectsBadSizes) {
  std::vector<float> a(10 * 10 * 3), b(10 * 10 * 3);
  EXPECT_THROW(photometric_loss(a, b, 10, 10, 0.2f, {}), std::invalid_argument);  // smaller than the window
  std::vector<float> c(12 * 12 * 3), d(12 * 12 * 3 - 1);
  EXPECT_THROW(photometric_loss(c, d, 12, 12, 0.2f, {}), std::invalid_argument);
}

// ---- The user's mask (keep: 1 = use, 0 = ignore) -------------------------------------------

// The masked loss from its definition: L1 over kept pixels; SSIM of keep·x against keep·y,
// averaged over the window positions whose center is kept.
double reference_masked_loss(const std::vector<double>& x, const std::vector<double>& y, const std::vector<float>& keep,
                             int w, int h, double lambda) {
  double l1 = 0, n = 0;
  for (size_t i = 0; i < x.size(); ++i) l1 += keep[i / 3] * std::abs(x[i] - y[i]), n += keep[i / 3];
  std::vector<double> kx(x.size()), ky(y.size());
  for (size_t i = 0; i < x.size(); ++i) kx[i] = keep[i / 3] * x[i], ky[i] = keep[i / 3] * y[i];
  return (1 - lambda) * l1 / n + lambda * (1 - reference_ssim(kx, ky, w, h, &keep));
}

// A blob of ignored pixels in a corner (covering some window centers, not all) plus a few
// scattered ones.
std::vector<float> test_mask(int w, int h) {
  std::vector<float> keep(size_t(w) * h, 1.0f);
  for (int y = 1; y < 6 && y < h; ++y)
    for (int x = 1; x < 8 && x < w; ++x) keep[y * w + x] = 0;
  for (int i = 0; i < w * h; i += 13) keep[i] = 0;
  return keep;
}

TEST(MaskedLoss, ValueMatchesItsDefinition) {
  for (auto [w, h] : {std::pair{17, 14}, std::pair{31, 23}}) {
    const Images im = random_images(w, h, 21);
    const std::vector<float> keep = test_mask(w, h);
    const std::vector<double> x(im.render.begin(), im.render.end()), y(im.target.begin(), im.target.end());
    const PhotometricLoss got = photometric_loss(im.render, im.target, w, h, 0.2f, {}, keep);
    EXPECT_NEAR(got.loss, reference_masked_loss(x, y, keep, w, h, 0.2), 2e-5) << w << "x" << h;
    EXPECT_NEAR(ssim(im.render, im.target, w, h, keep), got.ssim, 1e-12);
    // PSNR over the kept pixels only: the same as PSNR of the kept pixels gathered.
    std::vector<float> a, b;
    for (size_t i = 0; i < im.render.size(); ++i)
      if (keep[i / 3] != 0) a.push_back(im.render[i]), b.push_back(im.target[i]);
    EXPECT_NEAR(psnr(im.render, im.target, keep), psnr(a, b), 1e-9);
  }
}

TEST(MaskedLoss, GradientMatchesFiniteDifferencesAndIsZeroOnIgnoredPixels) {
  const int w = 17, h = 14;
  const Images im = random_images(w, h, 9);
  const std::vector<float> keep = test_mask(w, h);
  std::vector<float> grad(im.render.size());
  photometric_loss(im.render, im.target, w, h, 0.2f, grad, keep);
  std::vector<double> x(im.render.begin(), im.render.end());
  const std::vector<double> y(im.target.begin(), im.target.end());
  double scale = 0;
  std::vector<double> numeric(x.size());
  for (size_t i = 0; i < x.size(); ++i) {  // as in Loss.GradientMatchesFiniteDifferences
    const double v = x[i];
    x[i] = v + 1e-4;
    const double lp = reference_masked_loss(x, y, keep, w, h, 0.2);
    x[i] = v - 1e-4;
    const double lm = reference_masked_loss(x, y, keep, w, h, 0.2);
    x[i] = v;
    numeric[i] = (lp - lm) / 2e-4;
    scale = std::max(scale, std::abs(numeric[i]));
  }
  for (size_t i = 0; i < x.size(); ++i) {
    EXPECT_NEAR(grad[i], numeric[i], 1e-3 * scale) << i;
    if (keep[i / 3] == 0) {
      EXPECT_EQ(grad[i], 0.0f) << i;
    }
  }
}

TEST(MaskedLoss, IgnoredPixelsHaveNoInfluenceAndAllKeptIsTheUnmaskedLoss) {
  const int w = 23, h = 19;
  const Images im = random_images(w, h, 4);
  const std::vector<float> keep = test_mask(w, h);
  Images painted = im;  // anything at all where the mask says ignore, in both images
  for (size_t i = 0; i < painted.render.size(); ++i)
    if (keep[i / 3] == 0) painted.render[i] = 7.0f, painted.target[i] = float(i % 5);
  std::vector<float> g1(im.render.size()), g2(im.render.size());
  const PhotometricLoss a = photometric_loss(im.render, im.target, w, h, 0.2f, g1, keep);
  const PhotometricLoss b = photometric_loss(painted.render, painted.target, w, h, 0.2f, g2, keep);
  EXPECT_EQ(a.loss, b.loss);
  EXPECT_EQ(g1, g2);
  EXPECT_EQ(psnr(im.render, im.target, keep), psnr(painted.render, painted.target, keep));

  const std::vector<float> all(size_t(w) * h, 1.0f);
  std::vector<float> g3(im.render.size()), g4(im.render.size());
  const PhotometricLoss plain = photometric_loss(im.render, im.target, w, h, 0.2f, g3);
  const PhotometricLoss ones = photometric_loss(im.render, im.target, w, h, 0.2f, g4, all);
  EXPECT_EQ(plain.loss, ones.loss);
  EXPECT_EQ(g3, g4);

  const std::vector<float> none(size_t(w) * h, 0.0f);  // nothing kept: no loss, no gradient
  std::vector<float> g5(im.render.size(), 1.0f);
  EXPECT_EQ(photometric_loss(im.render, im.target, w, h, 0.2f, g5, none).loss, 0.0);
  for (float g : g5) EXPECT_EQ(g, 0.0f);
  std::vector<float> short_mask(10);
  EXPECT_THROW(photometric_loss(im.render, im.target, w, h, 0.2f, {}, short_mask), std::invalid_argument);
}

// The SSIM is computed in bands of rows, one per thread, and its backward reads across the
// bands' edges; L1 and PSNR are summed per row or chunk. Every thread count, including more
// threads than a band has rows, must give the same values and gradient, bit for bit, with and
// without a mask.
TEST(Loss, SameBitsOnAnyThreadCount) {
  const int saved = omp_get_max_threads();
  // 97×90 holds three of the PSNR's chunks of 4,096 pixels.
  for (const auto& [w, h] : {std::pair{40, 37}, std::pair{17, 13}, std::pair{11, 11}, std::pair{97, 90}})
    for (bool masked : {false, true}) {
      const Images im = random_images(w, h, 9), other = random_images(w, h, 10);
      const std::vector<float> keep = masked ? test_mask(w, h) : std::vector<float>{};
      std::vector<float> first_grad;
      PhotometricLoss first{};
      double first_psnr = 0;
      for (int threads : {1, 2, 3, 4, 7}) {
        omp_set_num_threads(threads);
        std::vector<float> grad(im.render.size());
        // Another pair first, so scratch left over from an earlier call holds other values.
        photometric_loss(other.render, other.target, w, h, 0.2f, grad, keep);
        std::fill(grad.begin(), grad.end(), 0.0f);
        const PhotometricLoss got = photometric_loss(im.render, im.target, w, h, 0.2f, grad, keep);
        const double got_psnr = psnr(im.render, im.target, keep);
        if (threads == 1) {
          first = got, first_grad = grad, first_psnr = got_psnr;
          continue;
        }
        EXPECT_EQ(got_psnr, first_psnr);
        EXPECT_EQ(got.loss, first.loss) << w << "x" << h << (masked ? " masked" : "") << ", " << threads << " threads";
        EXPECT_EQ(got.ssim, first.ssim);
        EXPECT_EQ(grad, first_grad) << w << "x" << h << (masked ? " masked" : "") << ", " << threads << " threads";
      }
    }
  omp_set_num_threads(saved);
}

}  // namespace
}  // namespace desplat
