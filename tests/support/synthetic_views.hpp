// A small scene with known ground truth for training tests: a ground-truth Gaussian
// set rendered from cameras on a circle of radius 1 (the scale docs/METHOD.md §1's
// normalization gives real captures, so default learning rates and thresholds apply). Every 4th camera is a held-out
// test view.
#pragma once

#include <cmath>
#include <random>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat::test {

inline Camera look_at_camera(float angle, float radius, int width, int height) {
  const float eye[3] = {radius * std::sin(angle), -0.16f * radius, -radius * std::cos(angle)};
  float f[3] = {-eye[0], -eye[1], -eye[2]}, n = 0;
  for (float v : f) n += v * v;
  for (float& v : f) v /= std::sqrt(n);
  float r[3] = {-f[2], 0, f[0]};  // (0,1,0) × f
  n = std::sqrt(r[0] * r[0] + r[2] * r[2]);
  for (float& v : r) v /= n;
  const float d[3] = {f[1] * r[2] - f[2] * r[1], f[2] * r[0] - f[0] * r[2], f[0] * r[1] - f[1] * r[0]};
  Camera c;
  c.width = width, c.height = height;
  c.fx = c.fy = 1.0f * width;
  c.cx = width * 0.5f, c.cy = height * 0.5f;
  c.R_cw = {r[0], r[1], r[2], d[0], d[1], d[2], f[0], f[1], f[2]};
  for (int row = 0; row < 3; ++row)
    c.t_cw[row] = -(c.R_cw[3 * row] * eye[0] + c.R_cw[3 * row + 1] * eye[1] + c.R_cw[3 * row + 2] * eye[2]);
  return c;
}

// Ground truth: `count` opaque-ish colored blobs inside the unit ball.
inline GaussianSet ground_truth_scene(int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1), c(0, 1);
  GaussianSet g;
  g.sh_degree = 0;
  g.resize(count);
  for (int i = 0; i < count; ++i) {
    float p[3], n2;
    do {
      n2 = 0;
      for (float& v : p) v = 0.28f * u(rng), n2 += v * v;
    } while (n2 > 0.28f * 0.28f);
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = p[k], g.log_scales[3 * i + k] = std::log(0.024f + 0.024f * c(rng));
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = u(rng);
    g.opacity_logits[i] = 2.0f;
    for (int k = 0; k < 3; ++k) g.colors[3 * i + k] = (c(rng) - 0.5f) / float(kShBand0);
  }
  return g;
}

inline TrainingData synthetic_training_data(int views, int width, int height, unsigned seed) {
  const GaussianSet truth = ground_truth_scene(120, seed);
  TrainingData data;
  const std::array<float, 3> bg{0.1490f, 0.1647f, 0.2157f};
  for (int v = 0; v < views; ++v) {
    TrainView view;
    view.name = "view_" + std::to_string(v);
    view.camera = look_at_camera(6.2831853f * v / views, 1.0f, width, height);
    RasterOutput out;
    rasterize_forward(truth.view(), view.camera, RasterSettings{}, out);
    FloatImage photo{width, height, 3, std::vector<float>(out.color.size())};
    for (size_t p = 0; p < out.alpha.size(); ++p)
      for (int c = 0; c < 3; ++c) photo.pixels[3 * p + c] = out.color[3 * p + c] + (1 - out.alpha[p]) * bg[c];
    view.image = to_bytes(photo);  // an 8-bit photo, as training holds one
    (v % 4 == 0 ? data.test : data.train).push_back(std::move(view));
  }
  // SfM-like points: the ground-truth centers, jittered, with their colors.
  std::mt19937 rng(seed + 1);
  std::normal_distribution<float> noise(0.0f, 0.012f);
  for (size_t i = 0; i < truth.size(); ++i) {
    data.points.push_back(
        {truth.means[3 * i] + noise(rng), truth.means[3 * i + 1] + noise(rng), truth.means[3 * i + 2] + noise(rng)});
    std::array<uint8_t, 3> rgb;
    for (int k = 0; k < 3; ++k)
      rgb[k] = uint8_t(std::lround(std::clamp(truth.colors[3 * i + k] * float(kShBand0) + 0.5f, 0.0f, 1.0f) * 255));
    data.colors.push_back(rgb);
  }
  return data;
}

// The schedule of a short training test on these views: SH degree 1 after 100 steps,
// factor 4, 2, then 1 after step 200, refinements every 50 steps from step 100, no opacity
// reset, 2 threads. Everything else is TrainConfig's default.
inline TrainConfig short_schedule(int64_t iterations) {
  TrainConfig c;
  c.iterations = iterations;
  c.sh_degree = 1;
  c.sh_degree_interval = 100;
  c.resolution_schedule = 100;
  c.densify.warmup = 100;
  c.densify.refine_every = 50;
  c.densify.reset_alpha_every = 1000;
  c.threads = 2;
  return c;
}

}  // namespace desplat::test
