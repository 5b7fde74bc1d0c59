// Initialization and per-view density control of distractor Gaussians.
#include "desplat/train/distractors.hpp"

#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>

#include "desplat/raster/raster.hpp"
#include "desplat/train/init.hpp"

namespace desplat {

int distractor_count_for(const Camera& cam, const DistractorSettings& s) {
  if (s.initial_count < 0 || s.reference_pixels < 0)
    throw std::invalid_argument("distractors: initial_count and reference_pixels must be ≥ 0");
  if (s.reference_pixels == 0 || s.initial_count == 0) return s.initial_count;
  const double pixels = double(cam.width) * double(cam.height);
  return int(std::max<long>(1, std::lround(s.initial_count * pixels / s.reference_pixels)));
}

void check_initial_distractors(const std::vector<Camera>& cameras, const DistractorSettings& s) {
  double total = 0;
  for (const Camera& cam : cameras) {
    const double count = distractor_count_for(cam, s), pixels = double(cam.width) * double(cam.height);
    if (count > pixels)
      throw std::invalid_argument(
          "distractors.initial_count (--distractors-per-view): " + std::to_string(int64_t(count)) +
          " initial distractors per view is more than a " + std::to_string(cam.width) + "x" +
          std::to_string(cam.height) + " training view has pixels (" + std::to_string(int64_t(pixels)) +
          "); a distractor Gaussian explains at least a pixel, so give at most that many");
    total += count;
  }
  const double physical = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
  const double need = total * kDistractorBytes;
  if (physical > 0 && need > physical) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "distractors.initial_count (--distractors-per-view): %.0f distractor Gaussians over %zu training "
                  "views need about %.1f GB, more than this machine's %.1f GB of memory; give fewer per view",
                  total, cameras.size(), need / 1e9, physical / 1e9);
    throw std::invalid_argument(text);
  }
}

GaussianSet init_distractors(const Camera& cam, const DistractorSettings& s, uint64_t seed) {
  if (!(s.init_depth > 0) || !(s.init_half_width > 0) || !(s.init_opacity > 0 && s.init_opacity < 1))
    throw std::invalid_argument("distractors: init_depth and init_half_width must be > 0, init_opacity in (0, 1)");
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> plane(-s.init_half_width, s.init_half_width), unit(0.0f, 1.0f);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const size_t n = size_t(distractor_count_for(cam, s));
  std::vector<std::array<float, 3>> world(n);
  for (size_t i = 0; i < n; ++i) {
    const double x = plane(rng), y = plane(rng);  // in this order: the seed's sequence stays as it was
    world[i] = cam.to_world({x, y, s.init_depth});
  }
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(n);
  const std::vector<float> dist = mean_knn_distance(world, 3);
  const float opacity_logit = std::log(s.init_opacity / (1 - s.init_opacity));
  for (size_t i = 0; i < n; ++i) {
    const float log_scale = std::log(std::max(dist[i], 1e-7f));
    const std::array<float, 4> q = random_unit_quaternion(rng, normal);
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = world[i][k], g.log_scales[3 * i + k] = log_scale;
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = q[k];
    g.opacity_logits[i] = opacity_logit;
    for (int c = 0; c < 3; ++c) g.colors[3 * i + c] = unit(rng);
  }
  return g;
}

bool distractor_refine_due(int64_t step, int num_train_views, const DensifySettings& d, const DistractorSettings& s) {
  if (!s.enabled || !s.density_control || !d.enabled) return false;
  if (step <= d.warmup || step % d.refine_every != 0) return false;
  const int64_t period = int64_t(s.refine_every_epochs) * std::max(1, num_train_views);
  return step % period < d.refine_every;
}

float distractor_size_threshold(const DensifySettings& d, const DistractorSettings& s, double scene_depth) {
  if (!s.size_threshold_at_scene_depth || !(scene_depth > 0.0)) return d.size_threshold;
  return float(double(d.size_threshold) * double(s.init_depth) / scene_depth);
}

RefineReport refine_distractors(TrainableGaussians& g, const DensifySettings& d, const DistractorSettings& s,
                                int64_t step, int image_size, std::mt19937_64& rng, int64_t max_new,
                                double scene_depth) {
  const bool densify = step < d.stop_split_at && step > s.grow_after;
  DensifySettings at_their_depth = d;
  at_their_depth.size_threshold = distractor_size_threshold(d, s, scene_depth);
  return apply_density_control(g, at_their_depth, step, image_size, densify, /*cull_unseen=*/true, rng, max_new);
}

int64_t cull_idle_distractors(TrainableGaussians& g, const Camera& camera, int factor, const DistractorSettings& s) {
  if (!(s.min_blend_weight > 0.0f) || g.size() == 0) return 0;
  if (factor < 1) throw std::invalid_argument("cull_idle_distractors: factor must be ≥ 1");
  RasterSettings rs;
  rs.num_threads = 1;
  RasterOutput render;
  rasterize_forward(g.params.view(), camera, rs, render);
  const std::vector<double> weight = blend_weights(render);
  // A pixel at the step's size covers factor² pixels at full training resolution.
  const double to_full_px = double(factor) * double(factor);
  std::vector<uint8_t> keep(g.size());
  int64_t culled = 0;
  for (size_t i = 0; i < g.size(); ++i) {
    keep[i] = weight[i] * to_full_px >= double(s.min_blend_weight);
    culled += !keep[i];
  }
  if (culled > 0) g.keep(keep);
  return culled;
}

double distractor_alpha_sum(const GaussianView& g, const Camera& camera) {
  if (g.size() == 0) return 0.0;
  RasterSettings rs;
  rs.num_threads = 1;
  RasterOutput projected;
  rasterize_project(g, camera, rs, projected);
  const double image = double(camera.width) * double(camera.height);
  double sum = 0.0;
  for (size_t i = 0; i < g.size(); ++i) {
    if (!projected.visible[i]) continue;
    // det Σ₂ = 1 / det(conic); ∫ o·exp(−½ dᵀ Σ₂⁻¹ d) = o·2π·√det Σ₂.
    const double a = projected.conics[3 * i], b = projected.conics[3 * i + 1], c = projected.conics[3 * i + 2];
    const double det_conic = a * c - b * b;
    if (!(det_conic > 0)) continue;
    sum += std::min(double(projected.opacity[i]) * 2.0 * M_PI / std::sqrt(det_conic), image);
  }
  return sum;
}

int64_t alpha_sum_budget(size_t buffer_size, double alpha_sum, double static_unexplained_fraction, int64_t pixels,
                         const DistractorSettings& s) {
  if (!(s.max_alpha_sum > 0.0f) || buffer_size == 0 || !(alpha_sum > 0.0)) return kUnlimitedGrowth;
  const double limit = double(s.max_alpha_sum) * std::clamp(static_unexplained_fraction, 0.0, 1.0) * double(pixels);
  if (alpha_sum >= limit) return 0;
  const double per_distractor = alpha_sum / double(buffer_size);
  return int64_t(std::floor((limit - alpha_sum) / per_distractor));
}

int64_t distractor_cap(double static_unexplained_fraction, int64_t pixels, const DistractorSettings& s) {
  if (s.pixels_per_distractor <= 0) return kUnlimitedGrowth;
  const double unexplained = std::clamp(static_unexplained_fraction, 0.0, 1.0) * double(pixels);
  return int64_t(std::floor(unexplained / s.pixels_per_distractor));
}

int64_t distractor_growth_budget(size_t buffer_size, double static_unexplained_fraction, int64_t pixels,
                                 const DistractorSettings& s) {
  const int64_t cap = distractor_cap(static_unexplained_fraction, pixels, s);
  return cap == kUnlimitedGrowth ? kUnlimitedGrowth : std::max<int64_t>(0, cap - int64_t(buffer_size));
}

bool distractor_buffer_starved(size_t buffer_size, double static_unexplained_fraction, int64_t pixels) {
  const double unexplained = static_unexplained_fraction * double(pixels);
  return static_unexplained_fraction > 0.01 && double(buffer_size) * 256.0 < unexplained;
}

int64_t uncovered_seed_count(size_t buffer_size, double static_unexplained_fraction,
                             double composite_unexplained_fraction, int64_t pixels, const DistractorSettings& s) {
  const double uncovered = std::clamp(composite_unexplained_fraction, 0.0, 1.0);
  if (!(uncovered > 0.01)) return 0;
  const int per = s.pixels_per_distractor > 0 ? s.pixels_per_distractor : 4;
  const int64_t wanted = int64_t(std::floor(uncovered * double(pixels) / per));
  const int64_t room = distractor_growth_budget(buffer_size, static_unexplained_fraction, pixels, s);
  return room == kUnlimitedGrowth ? wanted : std::min(wanted, room);
}

GaussianSet reseed_distractors(const Camera& cam, std::span<const uint8_t> mask, std::span<const float> target,
                               size_t count, const DistractorSettings& s, uint64_t seed) {
  const size_t pixels = size_t(cam.width) * size_t(cam.height);
  if (mask.size() != pixels || target.size() != 3 * pixels)
    throw std::invalid_argument("reseed_distractors: mask or target does not match the camera");
  std::vector<size_t> candidates;
  for (size_t p = 0; p < pixels; ++p)
    if (mask[p]) candidates.push_back(p);
  std::mt19937_64 rng(seed);
  std::shuffle(candidates.begin(), candidates.end(), rng);
  candidates.resize(std::min(count, candidates.size()));
  // A footprint of √A pixels: σ = ½·√A px at depth ρ is ρ·½·√A / f in world units.
  const double footprint_px = std::sqrt(double(s.pixels_per_distractor > 0 ? s.pixels_per_distractor : 4));
  const float log_scale = float(std::log(s.init_depth * 0.5 * footprint_px / std::max(cam.fx, cam.fy)));
  const float opacity_logit = std::log(s.init_opacity / (1 - s.init_opacity));
  std::normal_distribution<float> normal(0.0f, 1.0f);
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(candidates.size());
  for (size_t i = 0; i < candidates.size(); ++i) {
    const size_t p = candidates[i];
    const double u = double(p % cam.width) + 0.5, v = double(p / cam.width) + 0.5;
    const std::array<float, 3> w =
        cam.to_world({(u - cam.cx) / cam.fx * s.init_depth, (v - cam.cy) / cam.fy * s.init_depth, s.init_depth});
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = w[k], g.log_scales[3 * i + k] = log_scale;
    const std::array<float, 4> q = random_unit_quaternion(rng, normal);
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = q[k];
    g.opacity_logits[i] = opacity_logit;
    for (int c = 0; c < 3; ++c) g.colors[3 * i + c] = std::clamp(target[3 * p + c], 0.0f, 1.0f);
  }
  return g;
}

}  // namespace desplat
