// Shared by the COLMAP model tests: the fox model's location, file patching at documented byte
// offsets, a hand-made model using every camera model id, exact model comparison, and the real
// `colmap` executable for conversions.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "desplat/io/colmap.hpp"
#include "support/expect.hpp"
#include "support/fox_scene.hpp"
#include "support/temp_dir.hpp"

namespace colmap_test {

namespace fs = std::filesystem;
using namespace desplat::colmap;
using desplat::testing::slurp;
using desplat::testing::TempDir;

inline const fs::path kFoxDir = desplat::testing::fox_dir() / "sparse" / "0";

// ---- Small file helpers -------------------------------------------------------------------

// Replaces the file by unlinking it first: truncating an existing file makes ext4 flush it to
// disk on close (auto_da_alloc), which made the corruption sweep take seconds instead of ms.
inline void spit(const fs::path& path, const std::string& bytes) {
  fs::remove(path);
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

template <class T>
inline void patch(std::string& bytes, size_t offset, T value) {
  ASSERT_LE(offset + sizeof(T), bytes.size());
  std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

template <class T>
inline T peek(const std::string& bytes, size_t offset) {
  T value{};
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

// Record start offsets in images.bin / points3D.bin, walked with the documented layout
// (independent of the library's reader).
inline std::vector<size_t> image_records(const std::string& bin) {
  std::vector<size_t> starts;
  size_t pos = 8;
  for (uint64_t i = 0, n = peek<uint64_t>(bin, 0); i < n; ++i) {
    starts.push_back(pos);
    const size_t name_end = bin.find('\0', pos + 64);
    pos = name_end + 1 + 8 + 24 * peek<uint64_t>(bin, name_end + 1);
  }
  return starts;
}

inline std::vector<size_t> point_records(const std::string& bin) {
  std::vector<size_t> starts;
  size_t pos = 8;
  for (uint64_t i = 0, n = peek<uint64_t>(bin, 0); i < n; ++i) {
    starts.push_back(pos);
    pos += 51 + 8 * peek<uint64_t>(bin, pos + 43);
  }
  return starts;
}

// Copies fox's three .bin files into `dir` so a test can corrupt them.
inline fs::path copy_fox(const fs::path& dir) {
  fs::create_directories(dir);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    fs::remove(dir / f);  // see spit()
    fs::copy_file(kFoxDir / f, dir / f);
  }
  return dir;
}

// The ColmapError message `f` throws; a test failure if it throws nothing.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ColmapError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a ColmapError, none was thrown";
  return "";
}

// Checks that reading fails with a message naming `file` and containing every fragment.
inline void expect_error(const std::function<void()>& f, const fs::path& file,
                         std::initializer_list<std::string_view> fragments) {
  const std::string msg = error_of(f);
  EXPECT_NE(msg.find(file.string()), std::string::npos) << "message lacks the file: " << msg;
  for (std::string_view frag : fragments)
    EXPECT_NE(msg.find(frag), std::string::npos) << "message lacks '" << frag << "': " << msg;
}

// ---- Model comparison (doubles bit for bit) -----------------------------------------------

inline bool same_bits(double a, double b) { return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b); }

template <size_t N>
inline bool same_bits(const std::array<double, N>& a, const std::array<double, N>& b) {
  for (size_t k = 0; k < N; ++k)
    if (!same_bits(a[k], b[k])) return false;
  return true;
}

inline ::testing::AssertionResult identical(const Model& a, const Model& b) {
  using ::testing::AssertionFailure;
  if (a.cameras.size() != b.cameras.size() || a.images.size() != b.images.size() || a.points.size() != b.points.size())
    return AssertionFailure() << "sizes differ: cameras " << a.cameras.size() << "/" << b.cameras.size() << ", images "
                              << a.images.size() << "/" << b.images.size() << ", points " << a.points.size() << "/"
                              << b.points.size();
  for (auto ia = a.cameras.begin(), ib = b.cameras.begin(); ia != a.cameras.end(); ++ia, ++ib) {
    const Camera &x = ia->second, &y = ib->second;
    bool same = ia->first == ib->first && x.id == y.id && x.model == y.model && x.width == y.width &&
                x.height == y.height && x.params.size() == y.params.size();
    for (size_t k = 0; same && k < x.params.size(); ++k) same = same_bits(x.params[k], y.params[k]);
    if (!same) return AssertionFailure() << "camera " << ia->first << " differs";
  }
  for (auto ia = a.images.begin(), ib = b.images.begin(); ia != a.images.end(); ++ia, ++ib) {
    const Image &x = ia->second, &y = ib->second;
    bool same = ia->first == ib->first && x.id == y.id && same_bits(x.qvec_wxyz, y.qvec_wxyz) &&
                same_bits(x.tvec, y.tvec) && x.camera_id == y.camera_id && x.name == y.name &&
                x.points2d.size() == y.points2d.size();
    if (!same) return AssertionFailure() << "image " << ia->first << " header differs";
    for (size_t k = 0; k < x.points2d.size(); ++k) {
      const Observation &p = x.points2d[k], &q = y.points2d[k];
      if (!same_bits(p.x, q.x) || !same_bits(p.y, q.y) || p.point3d_id != q.point3d_id)
        return AssertionFailure() << "image " << ia->first << " points2D[" << k << "] differs";
    }
  }
  for (auto ia = a.points.begin(), ib = b.points.begin(); ia != a.points.end(); ++ia, ++ib) {
    const Point3D &x = ia->second, &y = ib->second;
    if (ia->first != ib->first || x.id != y.id || !same_bits(x.xyz, y.xyz) || x.rgb != y.rgb ||
        !same_bits(x.error, y.error) || x.track != y.track)
      return AssertionFailure() << "point3D " << ia->first << " differs";
  }
  return ::testing::AssertionSuccess();
}

// ---- The real colmap executable -----------------------------------------------------------

inline bool colmap_on_path() {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "");
  for (std::string dir; std::getline(dirs, dir, ':');)
    if (!dir.empty() && ::access((fs::path(dir) / "colmap").c_str(), X_OK) == 0) return true;
  return false;
}

// `colmap model_converter in -> out` (out is created; colmap requires it to exist).
inline ::testing::AssertionResult colmap_convert(const fs::path& in, const fs::path& out, const char* type) {
  if (!colmap_on_path())
    return ::testing::AssertionFailure() << "the `colmap` executable is not on PATH: run scripts/install_deps.sh "
                                            "(it installs COLMAP 3.8, which this test needs)";
  fs::create_directories(out);
  const fs::path log = out.string() + ".log";
  // Offscreen Qt: harmless for model_converter, and safe if a build ever wants a display.
  const std::string cmd = "QT_QPA_PLATFORM=offscreen colmap model_converter --input_path '" + in.string() +
                          "' --output_path '" + out.string() + "' --output_type " + type + " > '" + log.string() +
                          "' 2>&1";
  const int status = std::system(cmd.c_str());
  if (status != 0)
    return ::testing::AssertionFailure() << "`" << cmd << "` exited with status " << status << ":\n" << slurp(log);
  return ::testing::AssertionSuccess();
}

// ---- A hand-made model using every camera model id ----------------------------------------

// COLMAP's camera models (docs "Camera Models" / camera model source): id, name, #params.
struct ExpectedModel {
  int id;
  const char* name;
  int num_params;
};
inline constexpr ExpectedModel kExpectedModels[] = {
    {0, "SIMPLE_PINHOLE", 3},
    {1, "PINHOLE", 4},
    {2, "SIMPLE_RADIAL", 4},
    {3, "RADIAL", 5},
    {4, "OPENCV", 8},
    {5, "OPENCV_FISHEYE", 8},
    {6, "FULL_OPENCV", 12},
    {7, "FOV", 5},
    {8, "SIMPLE_RADIAL_FISHEYE", 4},
    {9, "RADIAL_FISHEYE", 5},
    {10, "THIN_PRISM_FISHEYE", 12},
};

// Doubles that a sloppy text or binary path would alter: thirds, −0, a subnormal, extremes.
inline constexpr double kAwkward[] = {512.3333333333334, 1.0 / 3.0, -0.0, 4.9406564584124654e-324, 1e-300,
                                      -2.5e-7,           1e300,     0.1,  123456789.123456789,     -7.0 / 3.0,
                                      2.0 / 3.0,         1e-5};

inline std::array<double, 4> unit_quat(double w, double x, double y, double z) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  return {w / n, x / n, y / n, z / n};
}

inline Model make_model() {
  Model m;
  for (const ExpectedModel& e : kExpectedModels) {
    Camera cam;
    cam.id = 100 + static_cast<uint32_t>(e.id);
    cam.model = static_cast<CameraModelId>(e.id);
    cam.width = 640 + static_cast<uint64_t>(e.id);
    cam.height = 480 + 2 * static_cast<uint64_t>(e.id);
    for (int k = 0; k < e.num_params; ++k)
      cam.params.push_back(kAwkward[static_cast<size_t>(k + e.id) % std::size(kAwkward)]);
    m.cameras[cam.id] = cam;
  }
  m.cameras[4000000000u] = Camera{4000000000u, CameraModelId::Pinhole, 1u << 20, 7, {1, 2, 3, 4}};

  const uint64_t big = (uint64_t{1} << 40) + 5;  // point ids are 64-bit
  Image a{1,
          unit_quat(0.9, 0.1, -0.2, 0.3),
          {0.5, -1.0 / 3.0, 1e-300},
          100,
          "a.jpg",
          {{1.5, 2.25, 7}, {3, 4, kNoPoint3D}, {5.125, 6.0 / 7.0, static_cast<int64_t>(big)}}};
  Image b{4000000001u,    unit_quat(-0.1, 0.7, 0.0, -0.7),
          {1e6, 2, -0.0}, 4000000000u,
          "sub/b.png",    {{0.0, -0.0, static_cast<int64_t>(big)}, {639.99, 479.99, 7}}};
  Image c{3, {1, 0, 0, 0}, {0, 0, 0}, 110, "c.jpg", {}};  // no observations
  for (Image* img : {&a, &b, &c}) m.images[img->id] = *img;

  m.points[7] = Point3D{7, {1, 2, 3}, {0, 128, 255}, 0.5, {{1, 0}, {4000000001u, 1}}};
  m.points[big] = Point3D{big, {-1e-3, 1.0 / 3.0, 1e5}, {1, 2, 3}, -1, {{4000000001u, 0}, {1, 2}}};
  return m;
}

// File sizes from the documented layout.
inline uint64_t expected_cameras_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, c] : m.cameras) n += 4 + 4 + 8 + 8 + 8 * c.params.size();
  return n;
}
inline uint64_t expected_images_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, i] : m.images) n += 4 + 32 + 24 + 4 + i.name.size() + 1 + 8 + 24 * i.points2d.size();
  return n;
}
inline uint64_t expected_points_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, p] : m.points) n += 8 + 24 + 3 + 8 + 8 + 8 * p.track.size();
  return n;
}

}  // namespace colmap_test
