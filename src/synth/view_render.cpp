// Supersampled ray tracing of one view.
#include "synth/view_render.hpp"

#include "desplat/io/camera_models.hpp"
#include "synth/random.hpp"

namespace desplat::synth {

SampleGrid make_sample_grid(const colmap::Camera& lens, int s, uint64_t seed) {
  SampleGrid grid;
  grid.width = static_cast<int>(lens.width);
  grid.height = static_cast<int>(lens.height);
  grid.samples = s * s;
  grid.uv.resize(static_cast<size_t>(grid.width) * grid.height * grid.samples);
#pragma omp parallel for schedule(dynamic, 4)
  for (int j = 0; j < grid.height; ++j) {
    Rng rng(seed, Stream::Jitter, static_cast<uint64_t>(j));  // one stream per row
    for (int i = 0; i < grid.width; ++i)
      for (int b = 0; b < s; ++b)
        for (int a = 0; a < s; ++a) {
          const double rx = s == 1 ? 0.5 : rng.uniform(), ry = s == 1 ? 0.5 : rng.uniform();
          const Vec2 xy{i + (a + rx) / s, j + (b + ry) / s};
          const Vec2 uv = camera_from_image(lens, xy);
          grid.uv[(static_cast<size_t>(j) * grid.width + i) * grid.samples + b * s + a] = {uv[0], uv[1]};
        }
  }
  return grid;
}

ViewRender render_view(const StaticScene& scene, const Primitives& distractors, const ViewPose& pose,
                       const SampleGrid& grid) {
  const int w = grid.width, h = grid.height, n = grid.samples;
  const bool has_distractors = !distractors.empty();
  ViewRender out;
  out.clean = FloatImage{w, h, 3, std::vector<float>(static_cast<size_t>(w) * h * 3)};
  out.mask = FloatImage{w, h, 1, std::vector<float>(static_cast<size_t>(w) * h)};
  if (has_distractors) out.cluttered = out.clean;
  float* clutter_px = has_distractors ? out.cluttered->pixels.data() : nullptr;
  const Eigen::Matrix3d R_wc = pose.R_cw.transpose();
  uint64_t tests = 0, sky = 0;
#pragma omp parallel for schedule(dynamic, 2) reduction(+ : tests, sky)
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      const size_t pixel = static_cast<size_t>(j) * w + i;
      Color clean = Color::Zero(), seen = Color::Zero();
      int covered = 0;
      for (int k = 0; k < n; ++k) {
        const Eigen::Vector2d& uv = grid.uv[pixel * n + k];
        const Ray ray{pose.center, (R_wc * Vec3(uv.x(), uv.y(), 1)).normalized()};
        const Hit hit = scene.objects.nearest(ray);
        Color c;
        if (hit.hit()) {
          c = scene.objects.shade(hit);
        } else {
          c = background_color(scene.world, scene.sky, ray.dir);
          sky += scene.sky.enabled ? 1 : 0;
        }
        clean += c;
        if (!has_distractors) continue;
        ++tests;
        const Hit front = distractors.nearest(ray, hit.t);
        if (front.hit()) {
          seen += distractors.shade(front);
          ++covered;
        } else {
          seen += c;
        }
      }
      for (int ch = 0; ch < 3; ++ch) {
        out.clean.pixels[pixel * 3 + ch] = static_cast<float>(clean[ch] / n);
        if (has_distractors) clutter_px[pixel * 3 + ch] = static_cast<float>(seen[ch] / n);
      }
      out.mask.pixels[pixel] = 2 * covered > n ? 1.0f : 0.0f;  // strict majority of the samples
    }
  }
  out.distractor_ray_tests = tests;
  out.sky_evaluations = sky;
  return out;
}

}  // namespace desplat::synth
