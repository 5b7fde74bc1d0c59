// Shared by the scene-loading tests: the fox capture, warnings collected instead of printed,
// pixel math written out independently of the loader, and small synthetic captures written
// with write_model_binary.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>
#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <unordered_map>
#include "desplat/io/camera_models.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/io/undistort.hpp"
#include "support/expect.hpp"
#include "support/fox_scene.hpp"
#include "support/look_at.hpp"
#include "support/temp_dir.hpp"

namespace scene_test {

namespace fs = std::filesystem;
using namespace desplat;
using colmap::CameraModelId;
using desplat::testing::error_of;
using desplat::testing::slurp;
using desplat::testing::spit;
using desplat::testing::TempDir;

inline const fs::path kFox = desplat::testing::fox_dir();

// Collects warnings instead of printing them.
struct Warnings {
  std::vector<std::string> seen;
  WarningSink sink() {
    return [this](const std::string& m) { seen.push_back(m); };
  }
};

inline SceneOptions quiet_options(const fs::path& cache, Warnings& w, int downscale = 1) {
  SceneOptions o;
  o.downscale = downscale;
  o.cache_dir = cache;
  o.on_warning = w.sink();
  return o;
}

inline std::array<double, 2> project(const Camera& cam, const std::array<double, 3>& x) {
  double p[3];
  for (int r = 0; r < 3; ++r)
    p[r] = double(cam.R_cw[3 * r]) * x[0] + double(cam.R_cw[3 * r + 1]) * x[1] + double(cam.R_cw[3 * r + 2]) * x[2] +
           double(cam.t_cw[r]);
  return {cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy};
}

inline Eigen::Matrix3d rotation(const colmap::Image& im) {
  // Hamilton quaternion (w, x, y, z) -> rotation matrix, written out.
  const double n = std::sqrt(im.qvec_wxyz[0] * im.qvec_wxyz[0] + im.qvec_wxyz[1] * im.qvec_wxyz[1] +
                             im.qvec_wxyz[2] * im.qvec_wxyz[2] + im.qvec_wxyz[3] * im.qvec_wxyz[3]);
  const double w = im.qvec_wxyz[0] / n, x = im.qvec_wxyz[1] / n, y = im.qvec_wxyz[2] / n, z = im.qvec_wxyz[3] / n;
  Eigen::Matrix3d R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),   //
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

inline Eigen::Vector3d center(const colmap::Image& im) {
  return -rotation(im).transpose() * Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]);
}

// (path, size, mtime) of every file under dir, to prove nothing was written there.
inline std::map<std::string, std::pair<uintmax_t, int64_t>> snapshot(const fs::path& dir) {
  std::map<std::string, std::pair<uintmax_t, int64_t>> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    files[e.path().string()] = {e.is_regular_file() ? e.file_size() : 0,
                                int64_t(e.last_write_time().time_since_epoch().count())};
  return files;
}

// 8-bit PNG round trip of the cache: values are rounded to k/255.
inline FloatImage quantized(FloatImage img) {
  for (float& v : img.pixels) v = std::round(std::clamp(v, 0.0f, 1.0f) * 255.0f) / 255.0f;
  return img;
}

inline double max_abs_diff(const FloatImage& a, const FloatImage& b) {
  if (a.width != b.width || a.height != b.height || a.pixels.size() != b.pixels.size()) return 1e9;
  double m = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) m = std::max(m, double(std::abs(a.pixels[i] - b.pixels[i])));
  return m;
}

inline FloatImage pattern_image(int w, int h, unsigned seed) {
  FloatImage img{w, h, 3, std::vector<float>(size_t(w) * h * 3)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        img.pixels[(size_t(y) * w + x) * 3 + c] =
            float(0.5 + 0.4 * std::sin(0.3 * x + 0.2 * y + c + seed) * std::cos(0.17 * y - 0.05 * x));
  return img;
}

FloatImage constant_image(int w, int h, float v) {
  return FloatImage{w, h, 3, std::vector<float>(size_t(w) * h * 3, v)};
}

// A small capture: `n` cameras on a ring looking at the origin, images named img_<i>.png.
struct Synthetic {
  colmap::Model model;
  std::vector<std::string> names;
};

inline Synthetic synthetic_model(CameraModelId lens, int n, int w, int h, int points) {
  Synthetic s;
  std::vector<double> params = lens == CameraModelId::Pinhole
                                   ? std::vector<double>{40.0, 41.0, w / 2.0, h / 2.0}
                                   : std::vector<double>{40.0, 41.0, w / 2.0, h / 2.0, -0.08, 0.02, 0.001, -0.002};
  s.model.cameras[1] = colmap::Camera{1, lens, uint64_t(w), uint64_t(h), params};
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d C(3 * std::cos(a), 0.3 * i / n, 3 * std::sin(a));
    const colmap::Image im = desplat::testing::look_at_origin(C, uint32_t(i + 1), "img_" + std::to_string(i) + ".png");
    s.names.push_back(im.name);
    s.model.images[im.id] = im;
  }
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int k = 0; k < points; ++k) {
    colmap::Point3D p;
    p.id = uint64_t(k + 1);
    p.xyz = {u(rng), u(rng), u(rng)};
    p.rgb = {uint8_t(k), 100, 200};
    s.model.points[p.id] = p;
  }
  return s;
}

// Writes the capture to dir: images/ (and the model) in the nerfstudio layout.
inline Synthetic write_synthetic(const fs::path& dir, CameraModelId lens = CameraModelId::Pinhole, int n = 4,
                                 int w = 64, int h = 48, int points = 20) {
  Synthetic s = synthetic_model(lens, n, w, h, points);
  colmap::write_model_binary(s.model, dir / "sparse/0");
  for (size_t i = 0; i < s.names.size(); ++i)
    write_image(dir / "images" / s.names[i], pattern_image(w, h, unsigned(i)));
  return s;
}

}  // namespace scene_test
