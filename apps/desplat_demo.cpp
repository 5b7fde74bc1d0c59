// desplat_demo: renders a built-in scene of Gaussians from a ring of cameras to PNG
// files. The first thing a newcomer runs; it exercises the whole forward kernel.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>
#include <random>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/trainer.hpp"

namespace {

using desplat::Camera;
using desplat::GaussianSet;

const std::array<float, 3> kEvalBackground = desplat::TrainConfig{}.eval_background;  // docs/METHOD.md §4

// A checkered floor, a hue-striped sphere and a ring of small glossy Gaussians.
GaussianSet demo_scene() {
  GaussianSet g;
  g.sh_degree = 1;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<std::array<float, 10>> items;  // x y z  log_scale(3)  r g b  opacity_logit
  for (int i = -40; i < 40; ++i)
    for (int j = -40; j < 40; ++j) {
      const float x = i * 0.05f + 0.025f, z = j * 0.05f + 0.025f;
      const float c = ((i / 8 + j / 8) & 1) ? 0.85f : 0.25f;
      items.push_back({x, 1.0f, z, std::log(0.03f), std::log(0.004f), std::log(0.03f), c, c, c * 0.9f, 3.0f});
    }
  for (int k = 0; k < 6000; ++k) {
    float p[3], n2 = 0;
    for (float& v : p) v = u(rng), n2 += v * v;
    const float n = std::sqrt(n2);
    const float x = 0.6f * p[0] / n, y = 0.6f * p[1] / n + 0.35f, z = 0.6f * p[2] / n;
    const float hue = 0.5f + std::atan2(z, x) / (2 * std::numbers::pi_v<float>);
    const float r = 0.5f + 0.5f * std::cos(6.2832f * hue), gr = 0.5f + 0.5f * std::cos(6.2832f * (hue - 0.333f)),
                b = 0.5f + 0.5f * std::cos(6.2832f * (hue - 0.667f));
    const float band = std::fmod(y * 6 + 10, 1.0f) < 0.15f ? 0.2f : 1.0f;
    items.push_back(
        {x, y, z, std::log(0.035f), std::log(0.035f), std::log(0.01f), r * band, gr * band, b * band, 2.0f});
  }
  for (int k = 0; k < 240; ++k) {
    const float a = 2 * std::numbers::pi_v<float> * k / 240;
    items.push_back({1.1f * std::cos(a), 0.3f + 0.15f * std::sin(3 * a), 1.1f * std::sin(a), std::log(0.03f),
                     std::log(0.03f), std::log(0.03f), 1.0f, 0.85f, 0.3f, 4.0f});
  }
  g.resize(items.size());
  const int stride = 3 * desplat::sh_coeff_count(g.sh_degree);
  for (size_t i = 0; i < items.size(); ++i) {
    const auto& it = items[i];
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = it[k], g.log_scales[3 * i + k] = it[3 + k];
    for (int c = 0; c < 3; ++c) g.colors[stride * i + c] = (it[6 + c] - 0.5f) / float(desplat::kShBand0);
    // A little view dependence on the ring: degree-1 band along y.
    if (i + 240 >= items.size()) g.colors[stride * i + 3 * 1 + 0] = -0.4f;
    g.quats[4 * i] = 1;
    g.opacity_logits[i] = it[9];
  }
  return g;
}

// Camera on a circle of radius 3 around the origin, slightly above, looking at (0, 0.3, 0), in
// COLMAP's convention (docs/METHOD.md §1): x right, y down, z forward, x_cam = R_cw·x + t_cw.
// The world's up is −y. glm::lookAtRH is OpenGL's view matrix (x right, y up, looking along
// −z), so its y and z rows are negated: R_cw = diag(1, −1, −1)·R_gl, t_cw = diag(1, −1, −1)·t_gl.
Camera orbit_camera(float angle, int width, int height) {
  const glm::vec3 eye(3.0f * std::sin(angle), -0.9f, -3.0f * std::cos(angle));
  const glm::vec3 target(0.0f, 0.3f, 0.0f), world_up(0.0f, -1.0f, 0.0f);
  const glm::mat4 view_gl = glm::lookAtRH(eye, target, world_up);
  const glm::mat3 gl_to_colmap(glm::vec3(1, 0, 0), glm::vec3(0, -1, 0), glm::vec3(0, 0, -1));  // by columns
  const glm::mat3 R_cw = gl_to_colmap * glm::mat3(view_gl);
  const glm::vec3 t_cw = gl_to_colmap * glm::vec3(view_gl[3]);
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.fx = cam.fy = 0.9f * width;
  cam.cx = width * 0.5f;
  cam.cy = height * 0.5f;
  for (int row = 0; row < 3; ++row) {  // GLM indexes [column][row]; Camera keeps R_cw row-major
    for (int col = 0; col < 3; ++col) cam.R_cw[3 * row + col] = R_cw[col][row];
    cam.t_cw[row] = t_cw[row];
  }
  return cam;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Render desplat's built-in demo scene of Gaussians to PNG files."};
  std::filesystem::path out_dir = "out/demo";
  int views = 8, width = 640, height = 480, threads = 0;
  app.add_option("--out", out_dir, "output folder for view_XX.png")->capture_default_str();
  app.add_option("--views", views, "number of cameras on the orbit")->check(CLI::Range(1, 360))->capture_default_str();
  app.add_option("--width", width, "image width [px]")->check(CLI::Range(1, 8192))->capture_default_str();
  app.add_option("--height", height, "image height [px]")->check(CLI::Range(1, 8192))->capture_default_str();
  app.add_option("--threads", threads, "OpenMP threads (0: all cores)")->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  try {
    const GaussianSet scene = demo_scene();
    desplat::RasterSettings settings;
    settings.num_threads = threads;
    desplat::RasterOutput out;
    std::printf("desplat_demo: %zu Gaussians, %d views at %dx%d\n", scene.size(), views, width, height);
    for (int v = 0; v < views; ++v) {
      const Camera cam = orbit_camera(2 * std::numbers::pi_v<float> * v / views, width, height);
      const auto t0 = std::chrono::steady_clock::now();
      desplat::rasterize_forward(scene.view(), cam, settings, out);
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      const desplat::FloatImage img = desplat::composite_over_background(out, kEvalBackground);
      char name[32];
      std::snprintf(name, sizeof name, "view_%02d.png", v);
      desplat::write_image(out_dir / name, img);
      std::printf("  %s  (render %.1f ms)\n", (out_dir / name).c_str(), ms);
    }
    std::printf("wrote %d PNG files to %s\n", views, std::filesystem::absolute(out_dir).c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "desplat_demo: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
