// One input gives bit-identical outputs and gradients for 1 and 2 threads (and for
// repeated runs): per-entry gradient records are reduced in a fixed order.
#include <gtest/gtest.h>

#include "desplat/raster/raster.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

TEST(Determinism, OneAndTwoThreadsAreBitIdentical) {
  std::mt19937 rng(42);
  const Camera cam = random_camera(rng, 150, 110, 120);
  SceneSpec spec;
  spec.count = 3000;
  spec.log_scale_min = -3.5f;
  spec.log_scale_max = -1.5f;
  const GaussianSet g = random_gaussians(rng, spec);
  std::normal_distribution<float> n(0, 1);
  const size_t pixels = size_t(cam.width) * cam.height;
  std::vector<float> wC(3 * pixels), wA(pixels), wD(pixels);
  for (auto* v : {&wC, &wA, &wD})
    for (float& x : *v) x = n(rng);

  RasterOutput out[3];
  RasterGradients grads[3];
  const int threads[3] = {1, 2, 2};
  for (int run = 0; run < 3; ++run) {
    RasterSettings s;
    s.num_threads = threads[run];
    rasterize_forward(g.view(), cam, s, out[run]);
    rasterize_backward(g.view(), cam, s, out[run], wC, wA, wD, grads[run]);
  }
  for (int run = 1; run < 3; ++run) {
    EXPECT_EQ(out[0].color, out[run].color);
    EXPECT_EQ(out[0].alpha, out[run].alpha);
    EXPECT_EQ(out[0].depth, out[run].depth);
    EXPECT_EQ(out[0].means2d, out[run].means2d);
    EXPECT_EQ(grads[0].means, grads[run].means);
    EXPECT_EQ(grads[0].log_scales, grads[run].log_scales);
    EXPECT_EQ(grads[0].quats, grads[run].quats);
    EXPECT_EQ(grads[0].opacity_logits, grads[run].opacity_logits);
    EXPECT_EQ(grads[0].colors, grads[run].colors);
    EXPECT_EQ(grads[0].absgrad, grads[run].absgrad);
  }
  // The scene is busy enough that both threads had tiles to share.
  EXPECT_GT(out[0].tile_entries.size(), 5000u);
}

}  // namespace
}  // namespace desplat::test
