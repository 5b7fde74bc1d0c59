// Scenes from COLMAP captures (scene.hpp): the real fox capture (read-only input) for
// geometry — every COLMAP observation must reproject onto its keypoint — normalization,
// downscaling and caching, and small synthetic captures written with write_model_binary for
// the images_N/ rules, the cache, and every kind of bad input.
//
// Independent expectations: COLMAP's own keypoints (images.bin) and 3D points, camera
// centers recomputed here from the raw quaternions, OpenCV-free pixel math written out in
// this file, and the documented binary layouts of images.bin / points3D.bin for corruption.
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

namespace fs = std::filesystem;
using namespace desplat;
using colmap::CameraModelId;

namespace {

const fs::path kFox = "/work/shared/data/fox";

// A fresh folder under the system temp dir, removed at the end of the test.
struct TempDir {
  fs::path path;
  explicit TempDir(const std::string& tag) {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("desplat_test_scene_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {  // gives write permission back first (the read-only test takes it away)
    std::error_code ec;
    fs::permissions(path, fs::perms::owner_all, fs::perm_options::add, ec);
    for (auto it = fs::recursive_directory_iterator(path, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec))
      fs::permissions(it->path(), fs::perms::owner_write | fs::perms::owner_exec, fs::perm_options::add, ec);
    fs::remove_all(path, ec);
  }
};

// Collects warnings instead of printing them.
struct Warnings {
  std::vector<std::string> seen;
  WarningSink sink() {
    return [this](const std::string& m) { seen.push_back(m); };
  }
};

SceneOptions quiet_options(const fs::path& cache, Warnings& w, int downscale = 1) {
  SceneOptions o;
  o.downscale = downscale;
  o.cache_dir = cache;
  o.on_warning = w.sink();
  return o;
}

template <class Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const SceneError& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("wrong exception type: ") + e.what();
  }
  return "no exception";
}

#define EXPECT_CONTAINS(haystack, needle) EXPECT_NE((haystack).find(needle), std::string::npos) << (haystack)

std::array<double, 2> project(const Camera& cam, const std::array<double, 3>& x) {
  double p[3];
  for (int r = 0; r < 3; ++r)
    p[r] = double(cam.R_cw[3 * r]) * x[0] + double(cam.R_cw[3 * r + 1]) * x[1] + double(cam.R_cw[3 * r + 2]) * x[2] +
           double(cam.t_cw[r]);
  return {cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy};
}

Eigen::Matrix3d rotation(const colmap::Image& im) {
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

Eigen::Vector3d center(const colmap::Image& im) {
  return -rotation(im).transpose() * Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]);
}

// (path, size, mtime) of every file under dir, to prove nothing was written there.
std::map<std::string, std::pair<uintmax_t, int64_t>> snapshot(const fs::path& dir) {
  std::map<std::string, std::pair<uintmax_t, int64_t>> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    files[e.path().string()] = {e.is_regular_file() ? e.file_size() : 0,
                                int64_t(e.last_write_time().time_since_epoch().count())};
  return files;
}

// 8-bit PNG round trip of the cache: values are rounded to k/255.
FloatImage quantized(FloatImage img) {
  for (float& v : img.pixels) v = std::round(std::clamp(v, 0.0f, 1.0f) * 255.0f) / 255.0f;
  return img;
}

double max_abs_diff(const FloatImage& a, const FloatImage& b) {
  if (a.width != b.width || a.height != b.height || a.pixels.size() != b.pixels.size()) return 1e9;
  double m = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) m = std::max(m, double(std::abs(a.pixels[i] - b.pixels[i])));
  return m;
}

FloatImage pattern_image(int w, int h, unsigned seed) {
  FloatImage img{w, h, 3, std::vector<float>(size_t(w) * h * 3)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        img.pixels[(size_t(y) * w + x) * 3 + c] =
            float(0.5 + 0.4 * std::sin(0.3 * x + 0.2 * y + c + seed) * std::cos(0.17 * y - 0.05 * x));
  return img;
}

FloatImage constant_image(int w, int h, float v) { return FloatImage{w, h, 3, std::vector<float>(size_t(w) * h * 3, v)}; }

// A small capture: `n` cameras on a ring looking at the origin, images named img_<i>.png.
struct Synthetic {
  colmap::Model model;
  std::vector<std::string> names;
};

Synthetic synthetic_model(CameraModelId lens, int n, int w, int h, int points) {
  Synthetic s;
  std::vector<double> params = lens == CameraModelId::Pinhole
                                   ? std::vector<double>{40.0, 41.0, w / 2.0, h / 2.0}
                                   : std::vector<double>{40.0, 41.0, w / 2.0, h / 2.0, -0.08, 0.02, 0.001, -0.002};
  s.model.cameras[1] = colmap::Camera{1, lens, uint64_t(w), uint64_t(h), params};
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d C(3 * std::cos(a), 0.3 * i / n, 3 * std::sin(a));
    const Eigen::Vector3d f = -C.normalized();
    const Eigen::Vector3d r = Eigen::Vector3d(0, 1, 0).cross(f).normalized();
    Eigen::Matrix3d R;
    R.row(0) = r;
    R.row(1) = f.cross(r);
    R.row(2) = f;
    const Eigen::Quaterniond q(R);
    const Eigen::Vector3d t = -R * C;
    colmap::Image im;
    im.id = uint32_t(i + 1);
    im.qvec_wxyz = {q.w(), q.x(), q.y(), q.z()};
    im.tvec = {t.x(), t.y(), t.z()};
    im.camera_id = 1;
    im.name = "img_" + std::to_string(i) + ".png";
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
Synthetic write_synthetic(const fs::path& dir, CameraModelId lens = CameraModelId::Pinhole, int n = 4, int w = 64,
                          int h = 48, int points = 20) {
  Synthetic s = synthetic_model(lens, n, w, h, points);
  colmap::write_model_binary(s.model, dir / "sparse/0");
  for (size_t i = 0; i < s.names.size(); ++i) write_image(dir / "images" / s.names[i], pattern_image(w, h, unsigned(i)));
  return s;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void spit(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << bytes;
}

}  // namespace

// ---- The fox capture -----------------------------------------------------------------------

// The check: every COLMAP observation of every registered image, projected with our
// undistorted pinhole camera after normalization, against its keypoint moved through the same
// undistortion. COLMAP's own fit of this capture leaves 17,121 of the 83,121 observations more
// than 1 px from their keypoints (its mapper keeps observations up to 4 px), so the 1 px rule is
// checked where COLMAP's own residual allows it, and our pipeline is checked exactly against
// COLMAP's model: whatever residual COLMAP has, ours is the same one, moved into the
// undistorted image.
TEST(FoxScene, EveryObservationReprojectsOntoItsUndistortedKeypoint) {
  Warnings w;
  TempDir cache("fox_reproj");
  const Scene scene = load_colmap_scene(kFox, quiet_options(cache.path, w));
  const colmap::Model model = colmap::read_model(kFox / "sparse/0");
  ASSERT_EQ(scene.views.size(), 50u);  // every registered image, train or test
  std::unordered_map<uint64_t, size_t> point_index;
  for (size_t i = 0; i < scene.point_ids.size(); ++i) point_index[scene.point_ids[i]] = i;
  ASSERT_EQ(point_index.size(), model.points.size());

  double max_err = 0, sum_err = 0, max_geometry = 0, max_colmap = 0, sum_colmap = 0;
  size_t n = 0, over_1px = 0, colmap_over_1px = 0;
  std::unordered_map<uint64_t, double> colmap_sum;  // per point, for COLMAP's stored mean error
  for (const SceneView& v : scene.views) {
    const colmap::Image& image = model.images.at(v.colmap_image_id);
    const colmap::Camera& lens = model.cameras.at(image.camera_id);
    const Eigen::Matrix3d R = rotation(image);
    for (const auto& obs : image.points2d) {
      if (obs.point3d_id < 0) continue;
      // Ours: the scene's normalized point through the scene's float pinhole camera.
      const auto& xyz = scene.points_xyz[point_index.at(uint64_t(obs.point3d_id))];
      const auto px = project(v.camera, {xyz[0], xyz[1], xyz[2]});
      const Vec2 keypoint = undistort_pixel(v.distorted_camera, v.undistorted_camera, {obs.x, obs.y});
      const double err = std::hypot(px[0] - keypoint[0], px[1] - keypoint[1]);
      // COLMAP's model: original frame, distorted lens, double precision.
      const auto& X = model.points.at(uint64_t(obs.point3d_id)).xyz;
      const Eigen::Vector3d p = R * Eigen::Vector3d(X[0], X[1], X[2]) +
                                Eigen::Vector3d(image.tvec[0], image.tvec[1], image.tvec[2]);
      const Vec2 model_px = image_from_camera(lens, {p.x() / p.z(), p.y() / p.z()});
      const double colmap_err = std::hypot(model_px[0] - obs.x, model_px[1] - obs.y);
      colmap_sum[uint64_t(obs.point3d_id)] += colmap_err;
      const Vec2 model_und = undistort_pixel(v.distorted_camera, v.undistorted_camera, model_px);
      max_geometry = std::max(max_geometry, std::hypot(px[0] - model_und[0], px[1] - model_und[1]));
      max_err = std::max(max_err, err);
      max_colmap = std::max(max_colmap, colmap_err);
      sum_colmap += colmap_err;
      sum_err += err;
      ++n;
      over_1px += err >= 1.0;
      colmap_over_1px += colmap_err >= 1.0;
      // The undistortion stretches the photo by at most ~6% locally (measured 1.058).
      EXPECT_LE(err, 1.1 * colmap_err + 0.01) << v.name << " point " << obs.point3d_id;
      if (colmap_err < 0.9) {
        EXPECT_LT(err, 1.0) << v.name << " point " << obs.point3d_id;
      }
    }
  }
  std::cout << n << " observations in " << scene.views.size() << " views: error max " << max_err << " px, mean "
            << sum_err / n << " px, " << over_1px << " at or above 1 px (COLMAP's own residuals in the photos: max "
            << max_colmap << " px, mean " << sum_colmap / n << " px, " << colmap_over_1px << " at or above 1 px)\n"
            << "  ours vs COLMAP's model projection moved through the undistortion: max " << max_geometry << " px\n";
  EXPECT_EQ(n, 83121u);  // data/README.md
  // Our normalization, pose conversion and undistortion add nothing to COLMAP's fit beyond
  // float rounding of the camera and point (measured 1e-4 px).
  EXPECT_LT(max_geometry, 0.01);
  // And the reference residuals are COLMAP's: their per-point means are the errors COLMAP
  // stored in points3D.bin.
  for (const auto& [id, point] : model.points)
    EXPECT_NEAR(colmap_sum.at(id) / double(point.track.size()), point.error, 1e-9) << "point " << id;
}

TEST(FoxScene, NormalizationCentersAndScalesTheCameras) {
  Warnings w;
  TempDir cache("fox_norm");
  const Scene scene = load_colmap_scene(kFox, quiet_options(cache.path, w));
  const colmap::Model model = colmap::read_model(kFox / "sparse/0");

  // Centers recomputed here from the raw quaternions, then normalized by the scene's transform.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double extent = 0;
  for (const auto& [id, im] : model.images) mean += center(im);
  mean /= double(model.images.size());
  for (const auto& [id, im] : model.images) extent = std::max(extent, (center(im) - mean).cwiseAbs().maxCoeff());
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(scene.normalization.center[k], mean[k], 1e-12 * (1 + std::abs(mean[k])));
  EXPECT_NEAR(scene.normalization.scale, 1 / extent, 1e-12 / extent);

  // The views' cameras (float) have centers with mean 0 and largest |coordinate| 1.
  std::array<double, 3> sum{0, 0, 0};
  double largest = 0;
  for (const SceneView& v : scene.views) {
    const auto c = v.camera.center();
    for (int k = 0; k < 3; ++k) {
      sum[k] += c[k];
      largest = std::max(largest, double(std::abs(c[k])));
    }
    // R stays orthonormal.
    const auto& R = v.camera.R_cw;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        const double dot = R[3 * a] * R[3 * b] + R[3 * a + 1] * R[3 * b + 1] + R[3 * a + 2] * R[3 * b + 2];
        EXPECT_NEAR(dot, a == b ? 1.0 : 0.0, 1e-6);
      }
  }
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(sum[k] / scene.views.size(), 0.0, 1e-6);
  EXPECT_NEAR(largest, 1.0, 1e-6);

  // There and back again.
  for (const auto& [id, p] : model.points) {
    const auto back = scene.normalization.to_original(scene.normalization.to_normalized(p.xyz));
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(back[k], p.xyz[k], 1e-12 * (1 + std::abs(p.xyz[k])));
    if (id > 200) break;
  }

  // A point projects to the same pixel in the original frame (COLMAP pose, double) and in
  // the normalized frame (the scene's float camera and point).
  const SceneView& v = scene.views[17];
  const colmap::Image& im = model.images.at(v.colmap_image_id);
  const Eigen::Matrix3d R = rotation(im);
  const PinholeIntrinsics K = pinhole_intrinsics(v.undistorted_camera);
  for (size_t i = 0; i < scene.points_xyz.size(); i += 97) {
    const auto& X = model.points.at(scene.point_ids[i]).xyz;
    const Eigen::Vector3d p = R * Eigen::Vector3d(X[0], X[1], X[2]) + Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]);
    if (p.z() <= 0) continue;
    const auto& xn = scene.points_xyz[i];
    const auto px = project(v.camera, {xn[0], xn[1], xn[2]});
    EXPECT_NEAR(px[0], K.fx * p.x() / p.z() + K.cx, 2e-3);  // float camera and point
    EXPECT_NEAR(px[1], K.fy * p.y() / p.z() + K.cy, 2e-3);
  }
}

TEST(FoxScene, ViewsAreSortedAndEveryEighthIsATestView) {
  Warnings w;
  TempDir cache("fox_split");
  const Scene scene = load_colmap_scene(kFox, quiet_options(cache.path, w));
  for (size_t i = 1; i < scene.views.size(); ++i) EXPECT_LT(scene.views[i - 1].name, scene.views[i].name);
  for (size_t i = 0; i < scene.views.size(); ++i) EXPECT_EQ(scene.views[i].is_test, i % 8 == 0) << i;
  EXPECT_EQ(scene.test_views(), (std::vector<size_t>{0, 8, 16, 24, 32, 40, 48}));
  EXPECT_EQ(scene.train_views().size(), 43u);
  EXPECT_EQ(scene.points_xyz.size(), 12421u);  // data/README.md
  EXPECT_TRUE(w.seen.empty());
  // The undistorted camera COLMAP chooses for this lens (test_undistort checks it against colmap).
  EXPECT_EQ(scene.views[0].camera.width, 530);
  EXPECT_EQ(scene.views[0].camera.height, 946);
}

TEST(FoxScene, FullResolutionImageIsTheUndistortedPhoto) {
  Warnings w;
  TempDir cache("fox_full");
  const auto before = snapshot(kFox);
  const Scene scene = load_colmap_scene(kFox, quiet_options(cache.path, w));
  const SceneView& v = scene.views[3];
  const FloatImage img = load_view_image(scene, 3);
  const FloatImage expected =
      undistort_image(read_image_rgb(kFox / "images" / v.name), v.distorted_camera, v.undistorted_camera);
  EXPECT_LE(max_abs_diff(img, quantized(expected)), 1.01 / 255);  // 8-bit cache: ±1 level at rounding ties
  EXPECT_EQ(snapshot(kFox), before);  // nothing written into the input
  EXPECT_EQ(view_cache_path(scene, 3).parent_path().parent_path(), fs::absolute(cache.path));
}

TEST(FoxScene, DownscaleResizesThenUndistortsIntoTheCacheNotTheInput) {
  Warnings w;
  TempDir cache("fox_down");
  const auto before = snapshot(kFox);
  const Scene scene = load_colmap_scene(kFox, quiet_options(cache.path, w, 2));
  const SceneView& v = scene.views[5];
  // The lens at 270x480, then COLMAP's undistorted camera of it.
  const colmap::Model model = colmap::read_model(kFox / "sparse/0");
  const colmap::Camera lens = model.cameras.begin()->second;
  EXPECT_EQ(v.distorted_camera.width, 270u);
  EXPECT_EQ(v.distorted_camera.height, 480u);
  EXPECT_DOUBLE_EQ(v.distorted_camera.params[0], lens.params[0] / 2);
  EXPECT_DOUBLE_EQ(v.distorted_camera.params[3], lens.params[3] / 2);
  const colmap::Camera pinhole = undistort_camera(rescale_camera(lens, 270, 480));
  EXPECT_EQ(uint64_t(v.camera.width), pinhole.width);
  EXPECT_EQ(uint64_t(v.camera.height), pinhole.height);
  EXPECT_FLOAT_EQ(v.camera.fx, float(pinhole.params[0]));
  EXPECT_FLOAT_EQ(v.camera.cx, float(pinhole.params[2]));
  EXPECT_EQ(v.image_path, kFox / "images" / v.name);  // no images_2/ here

  const FloatImage img = load_view_image(scene, 5);
  const FloatImage expected =
      undistort_image(resize_area(read_image_rgb(kFox / "images" / v.name), 270, 480), v.distorted_camera,
                      v.undistorted_camera);
  EXPECT_LE(max_abs_diff(img, quantized(expected)), 1.01 / 255);
  const fs::path cached = view_cache_path(scene, 5);
  EXPECT_TRUE(fs::exists(cached));
  EXPECT_EQ(cached.string().rfind(fs::absolute(cache.path).string(), 0), 0u) << cached;
  EXPECT_EQ(snapshot(kFox), before);  // the read-only input is untouched
}

// ---- images_N/ and the cache (synthetic captures) ------------------------------------------

TEST(SceneDownscale, UsesImagesNWhenItsSizesMatch) {
  for (const auto& [w, h, w2, h2] : {std::array<int, 4>{64, 48, 32, 24}, {65, 49, 32, 24}, {65, 49, 33, 25}}) {
    TempDir dir("images_n");
    TempDir cache("images_n_cache");
    write_synthetic(dir.path, CameraModelId::Pinhole, 4, w, h);
    for (int i = 0; i < 4; ++i)
      write_image(dir.path / "images_2" / ("img_" + std::to_string(i) + ".png"), constant_image(w2, h2, 0.8f));
    Warnings warn;
    const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, warn, 2));
    EXPECT_TRUE(warn.seen.empty()) << warn.seen.front();
    const SceneView& v = scene.views[1];
    EXPECT_EQ(v.image_path, fs::absolute(dir.path) / "images_2" / v.name);
    EXPECT_EQ(v.camera.width, w2);  // the folder's size (floor or round of W/2) is the training size
    EXPECT_EQ(v.camera.height, h2);
    EXPECT_DOUBLE_EQ(v.undistorted_camera.params[0], 40.0 * w2 / w);  // intrinsics follow the actual size
    EXPECT_DOUBLE_EQ(v.undistorted_camera.params[2], w / 2.0 * w2 / w);
    EXPECT_TRUE(view_cache_path(scene, 1).empty());  // pinhole at its own size: read directly
    EXPECT_LE(max_abs_diff(load_view_image(scene, 1), quantized(constant_image(w2, h2, 0.8f))), 1e-6);  // the file as is
    EXPECT_FALSE(fs::exists(cache.path / "views"));
  }
}

TEST(SceneDownscale, IgnoresAMismatchedImagesNWithAWarning) {
  TempDir dir("images_n_bad");
  TempDir cache("images_n_bad_cache");
  write_synthetic(dir.path, CameraModelId::Pinhole, 4, 64, 48);
  for (int i = 0; i < 4; ++i)
    write_image(dir.path / "images_2" / ("img_" + std::to_string(i) + ".png"), constant_image(30, 20, 0.8f));
  Warnings warn;
  const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, warn, 2));
  ASSERT_EQ(warn.seen.size(), 1u);
  EXPECT_CONTAINS(warn.seen[0], "images_2");
  EXPECT_CONTAINS(warn.seen[0], "30x20");
  EXPECT_EQ(scene.warnings, warn.seen);
  const SceneView& v = scene.views[2];
  EXPECT_EQ(v.image_path, fs::absolute(dir.path) / "images" / v.name);
  EXPECT_EQ(v.camera.width, 32);
  EXPECT_EQ(v.camera.height, 24);
  const FloatImage expected = resize_area(read_image_rgb(dir.path / "images" / v.name), 32, 24);
  EXPECT_LE(max_abs_diff(load_view_image(scene, 2), quantized(expected)), 1.01 / 255);
}

TEST(SceneCache, IsReusedAndInvalidatedWhenTheSourceChanges) {
  TempDir dir("cache");
  TempDir cache("cache_dir");
  write_synthetic(dir.path, CameraModelId::OpenCV, 4, 64, 48);
  Warnings warn;
  const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, warn));
  const fs::path cached = view_cache_path(scene, 0);
  ASSERT_FALSE(cached.empty());  // OPENCV: undistorted, hence cached
  EXPECT_FALSE(fs::exists(cached));
  const FloatImage first = load_view_image(scene, 0);
  ASSERT_TRUE(fs::exists(cached));

  // Reused: a marker written over the cache file comes back.
  const FloatImage marker = constant_image(first.width, first.height, 0.25f);
  write_image(cached, marker);
  EXPECT_LE(max_abs_diff(load_view_image(scene, 0), quantized(marker)), 1e-7);

  // A newer source file (same bytes) gets a new cache file; the marker is never used again.
  const fs::path source = dir.path / "images" / scene.views[0].name;
  fs::last_write_time(source, fs::last_write_time(source) + std::chrono::seconds(5));
  const fs::path refreshed = view_cache_path(scene, 0);
  EXPECT_NE(refreshed, cached);
  EXPECT_EQ(max_abs_diff(load_view_image(scene, 0), first), 0.0);
  EXPECT_TRUE(fs::exists(refreshed));

  // A different camera (other downscale) never shares a cache file either.
  const Scene half = load_colmap_scene(dir.path, quiet_options(cache.path, warn, 2));
  EXPECT_NE(view_cache_path(half, 0), refreshed);
  EXPECT_EQ(load_view_image(half, 0).width, half.views[0].camera.width);
  EXPECT_TRUE(warn.seen.empty());
}

TEST(SceneCache, WorksWithAReadOnlyInput) {
  TempDir dir("readonly");
  TempDir cache("readonly_cache");
  write_synthetic(dir.path, CameraModelId::OpenCV, 4, 64, 48);
  for (const auto& e : fs::recursive_directory_iterator(dir.path))
    fs::permissions(e.path(), fs::perms::owner_write | fs::perms::group_write | fs::perms::others_write,
                    fs::perm_options::remove);
  fs::permissions(dir.path, fs::perms::owner_write, fs::perm_options::remove);
  const auto before = snapshot(dir.path);
  Warnings warn;
  const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, warn, 2));
  for (size_t i = 0; i < scene.views.size(); ++i) EXPECT_EQ(load_view_image(scene, i).width, scene.views[i].camera.width);
  EXPECT_EQ(snapshot(dir.path), before);  // (as root, permissions alone would not have stopped a write)
}

// ---- Bad input ------------------------------------------------------------------------------

TEST(SceneErrors, MissingFolders) {
  TempDir dir("missing");
  write_synthetic(dir.path);
  Warnings w;
  TempDir cache("missing_cache");
  fs::rename(dir.path / "images", dir.path / "photos");
  std::string e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path) / "images").string());
  EXPECT_CONTAINS(e, "missing images/ folder");
  fs::rename(dir.path / "photos", dir.path / "images");
  fs::rename(dir.path / "sparse/0", dir.path / "sparse/1");
  e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path) / "sparse/0").string());
  EXPECT_CONTAINS(e, "missing sparse/0/ folder");
  EXPECT_CONTAINS(error_of([&] { load_colmap_scene(dir.path / "nowhere", quiet_options(cache.path, w)); }),
                  "nowhere: missing scene folder");
}

TEST(SceneErrors, RegisteredImageWithoutAFile) {
  TempDir dir("nofile");
  TempDir cache("nofile_cache");
  write_synthetic(dir.path);
  fs::remove(dir.path / "images/img_2.png");
  Warnings w;
  const std::string e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path) / "images/img_2.png").string());
  EXPECT_CONTAINS(e, "no file for image 'img_2.png' (image id 3 in");
  EXPECT_CONTAINS(e, "images.bin");
}

TEST(SceneErrors, ImageSizeDisagreesWithItsCamera) {
  TempDir dir("size");
  TempDir cache("size_cache");
  write_synthetic(dir.path);
  write_image(dir.path / "images/img_1.png", pattern_image(63, 48, 1));
  Warnings w;
  std::string e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, "img_1.png: image is 63x48 px but its COLMAP camera 1 is 64x48 px");
  // A downscaled photo in images/ is not explained by the downscale (that is images_N/'s job).
  write_image(dir.path / "images/img_1.png", pattern_image(32, 24, 1));
  e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w, 2)); });
  EXPECT_CONTAINS(e, "img_1.png: image is 32x24 px but its COLMAP camera 1 is 64x48 px");
}

TEST(SceneErrors, UnreadableOrCorruptImages) {
  TempDir dir("corrupt");
  TempDir cache("corrupt_cache");
  write_synthetic(dir.path);
  Warnings w;
  const fs::path bad = dir.path / "images/img_0.png";
  spit(bad, "this is not an image");
  std::string e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, fs::absolute(bad).string());
  EXPECT_CONTAINS(e, "cannot read image");
  // A truncated file whose header is intact passes the load and fails when its pixels are read.
  write_image(bad, pattern_image(64, 48, 0));
  const std::string bytes = slurp(bad);
  spit(bad, bytes.substr(0, bytes.size() / 2));
  const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, w));
  e = error_of([&] { load_view_image(scene, 0); });
  EXPECT_CONTAINS(e, fs::absolute(bad).string());
}

TEST(SceneErrors, ModelProblemsReportedByTheColmapReader) {
  TempDir dir("model");
  TempDir cache("model_cache");
  write_synthetic(dir.path);
  Warnings w;
  const fs::path images_bin = dir.path / "sparse/0/images.bin";
  const fs::path points_bin = dir.path / "sparse/0/points3D.bin";
  const std::string images = slurp(images_bin), points = slurp(points_bin);

  // Duplicate names: rename img_1.png to img_0.png in place (same length).
  std::string dup = images;
  const size_t at = dup.find("img_1.png");
  ASSERT_NE(at, std::string::npos);
  dup[at + 4] = '0';
  spit(images_bin, dup);
  std::string e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, images_bin.string());
  EXPECT_CONTAINS(e, "duplicate image name 'img_0.png'");

  // NaN in a pose: images.bin = uint64 count, then per image uint32 id, qw qx qy qz tx ty tz.
  std::string nan_pose = images;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(nan_pose.data() + 8 + 4 + 4 * 8, &nan, 8);  // tx of the first image
  spit(images_bin, nan_pose);
  e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, images_bin.string());
  EXPECT_CONTAINS(e, "tx is nan");
  spit(images_bin, images);

  // Inf in a point: points3D.bin = uint64 count, then per point uint64 id, x y z.
  std::string inf_point = points;
  const double inf = std::numeric_limits<double>::infinity();
  std::memcpy(inf_point.data() + 8 + 8 + 8, &inf, 8);  // y of the first point
  spit(points_bin, inf_point);
  e = error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w)); });
  EXPECT_CONTAINS(e, points_bin.string());
  EXPECT_CONTAINS(e, "y is inf");
}

TEST(SceneErrors, EmptyPointCloudLoadsWithAWarning) {
  TempDir dir("nopoints");
  TempDir cache("nopoints_cache");
  write_synthetic(dir.path, CameraModelId::Pinhole, 4, 64, 48, /*points=*/0);
  Warnings w;
  const Scene scene = load_colmap_scene(dir.path, quiet_options(cache.path, w));
  EXPECT_TRUE(scene.points_xyz.empty());
  EXPECT_TRUE(scene.points_rgb.empty());
  ASSERT_EQ(w.seen.size(), 1u);
  EXPECT_CONTAINS(w.seen[0], "no 3D points");
  EXPECT_EQ(scene.views.size(), 4u);
}

TEST(SceneErrors, BadOptionsAndSplits) {
  TempDir dir("options");
  TempDir cache("options_cache");
  write_synthetic(dir.path);
  Warnings w;
  EXPECT_CONTAINS(error_of([&] { load_colmap_scene(dir.path, quiet_options(cache.path, w, 0)); }),
                  "downscale must be at least 1");
  SceneOptions o = quiet_options(cache.path, w);
  o.split.rule = SplitRule::RobustNeRF;  // img_*.png has none of the RobustNeRF keywords
  EXPECT_CONTAINS(error_of([&] { load_colmap_scene(dir.path, o); }), "'img_0.png' must contain exactly one of");
  o.split.rule = SplitRule::OnTheGo;
  o.split.every_nth = 4;  // belongs to another rule
  EXPECT_CONTAINS(error_of([&] { load_colmap_scene(dir.path, o); }), "does not use every_nth");
  EXPECT_CONTAINS(error_of([&] { load_colmap_scene(dir.path, quiet_options(dir.path / "images/.cache", w)); }),
                  "the image cache must be outside the input folder");
  EXPECT_CONTAINS(error_of([&] {
                    const Scene s = load_colmap_scene(dir.path, quiet_options(cache.path, w));
                    load_view_image(s, 99);
                  }),
                  "view 99 does not exist");
}

TEST(SceneLoad, TextModelsAndUnusedViews) {
  TempDir dir("text");
  TempDir cache("text_cache");
  const Synthetic s = write_synthetic(dir.path, CameraModelId::Pinhole, 6, 64, 48);
  fs::remove_all(dir.path / "sparse/0");
  colmap::write_model_text(s.model, dir.path / "sparse/0");
  std::ofstream(dir.path / "train.txt") << "img_1.png\nimg_3.png\n";
  std::ofstream(dir.path / "test.txt") << "img_5.png\n";
  Warnings w;
  SceneOptions o = quiet_options(cache.path, w);
  o.split.rule = SplitRule::NameLists;
  o.split.train_list = dir.path / "train.txt";
  o.split.test_list = dir.path / "test.txt";
  const Scene scene = load_colmap_scene(dir.path, o);
  ASSERT_EQ(scene.views.size(), 3u);  // the other three are unused
  EXPECT_EQ(scene.views[0].name, "img_1.png");
  EXPECT_FALSE(scene.views[0].is_test);
  EXPECT_TRUE(scene.views[2].is_test);
  // Normalization still uses all six cameras.
  double largest = 0;
  for (const auto& [id, im] : s.model.images) {
    const auto c = scene.normalization.to_normalized({center(im).x(), center(im).y(), center(im).z()});
    for (double v : c) largest = std::max(largest, std::abs(v));
  }
  EXPECT_NEAR(largest, 1.0, 1e-12);
}

TEST(SceneLoad, SingleCameraKeepsTheScale) {
  TempDir dir("single");
  TempDir cache("single_cache");
  const Synthetic s = write_synthetic(dir.path, CameraModelId::Pinhole, 1, 64, 48);
  Warnings w;
  SceneOptions o = quiet_options(cache.path, w);
  o.split.rule = SplitRule::AllTrain;  // every-8th would hold out the only view
  const Scene scene = load_colmap_scene(dir.path, o);
  EXPECT_EQ(scene.normalization.scale, 1.0);
  const Eigen::Vector3d c = center(s.model.images.begin()->second);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(scene.normalization.center[k], c[k], 1e-12);
  for (float v : scene.views[0].camera.center()) EXPECT_NEAR(v, 0.0f, 1e-6f);
}
