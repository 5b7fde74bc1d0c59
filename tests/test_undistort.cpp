// Undistortion (undistort.hpp) against the real `colmap image_undistorter` (COLMAP 3.8, its
// default options) on the fox capture, and against analytic images.
//
// COLMAP undistorts 3 of the 50 fox photos (--image_list_path) into a temporary folder; its
// output model (cameras.bin: the chosen PINHOLE camera; images.bin: every keypoint of all 50
// images moved into the undistorted image) and its JPEGs are the expectations.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <random>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/io/undistort.hpp"
#include "support/fox_scene.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using colmap::CameraModelId;

namespace {

const fs::path kFox = desplat::testing::fox_dir();
const std::vector<std::string> kSubset = {"0001.jpg", "0042.jpg", "0115.jpg"};  // first, 25th, last

// Runs COLMAP once for the whole file.
class ColmapUndistorter : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("desplat_test_undistort_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    std::ofstream list(dir_ / "list.txt");
    for (const auto& name : kSubset) list << name << "\n";
    list.close();
    const std::string cmd = "colmap image_undistorter --image_path " + (kFox / "images").string() + " --input_path " +
                            (kFox / "sparse/0").string() + " --output_path " + (dir_ / "out").string() +
                            " --output_type COLMAP --image_list_path " + (dir_ / "list.txt").string() + " > " +
                            (dir_ / "colmap.log").string() + " 2>&1";
    status_ = std::system(cmd.c_str());
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  void SetUp() override { ASSERT_EQ(status_, 0) << "colmap image_undistorter failed, see " << dir_ / "colmap.log"; }

  static inline fs::path dir_;
  static inline int status_ = -1;
};

struct DiffStats {
  double mean = 0, p99 = 0, max = 0;
};

// Absolute differences over all channels of the pixels at least `margin` px from the border.
DiffStats compare(const FloatImage& a, const FloatImage& b, int margin) {
  std::vector<float> d;
  for (int y = margin; y < a.height - margin; ++y)
    for (int x = margin; x < a.width - margin; ++x)
      for (int c = 0; c < 3; ++c) {
        const size_t i = (size_t(y) * a.width + x) * 3 + c;
        d.push_back(std::abs(a.pixels[i] - b.pixels[i]));
      }
  DiffStats s;
  double sum = 0;
  for (float v : d) sum += v;
  s.mean = sum / d.size();
  std::sort(d.begin(), d.end());
  s.p99 = d[size_t(0.99 * (d.size() - 1))];
  s.max = d.back();
  return s;
}

// Geometric misregistration of b against a: a least-squares (Lucas–Kanade) fit of
// b(p) ≈ a(p + d(p)) over the whole image, with d(p) = (t_x + s_x·(x − W/2), t_y + s_y·(y − H/2))
// (grey = channel mean). Intensity noise (JPEG, interpolation) averages out over 500k
// pixels; a wrong principal point shows up in t, a wrong focal length or size in s.
struct Registration {
  double tx, ty;          // [px]
  double edge_x, edge_y;  // s·W/2, s·H/2: the displacement the scale terms cause at the border [px]
};

Registration register_images(const FloatImage& a, const FloatImage& b) {
  const auto grey = [](const FloatImage& im, int x, int y) {
    const float* p = &im.pixels[(size_t(y) * im.width + x) * 3];
    return (p[0] + p[1] + p[2]) / 3.0;
  };
  const double cx = a.width / 2.0, cy = a.height / 2.0;
  double A[4][4] = {}, r[4] = {};
  for (int y = 4; y < a.height - 4; ++y)
    for (int x = 4; x < a.width - 4; ++x) {
      const double gx = (grey(a, x + 1, y) - grey(a, x - 1, y)) / 2;
      const double gy = (grey(a, x, y + 1) - grey(a, x, y - 1)) / 2;
      const double J[4] = {gx, gy, gx * (x - cx), gy * (y - cy)};
      const double e = grey(b, x, y) - grey(a, x, y);
      for (int i = 0; i < 4; ++i) {
        r[i] += J[i] * e;
        for (int j = 0; j < 4; ++j) A[i][j] += J[i] * J[j];
      }
    }
  // Gaussian elimination on the 4x4 normal equations (symmetric positive definite).
  for (int i = 0; i < 4; ++i)
    for (int k = i + 1; k < 4; ++k) {
      const double f = A[k][i] / A[i][i];
      for (int j = i; j < 4; ++j) A[k][j] -= f * A[i][j];
      r[k] -= f * r[i];
    }
  double d[4];
  for (int i = 3; i >= 0; --i) {
    d[i] = r[i];
    for (int j = i + 1; j < 4; ++j) d[i] -= A[i][j] * d[j];
    d[i] /= A[i][i];
  }
  return {d[0], d[1], d[2] * cx, d[3] * cy};
}

}  // namespace

TEST_F(ColmapUndistorter, ChoosesColmapsPinholeCamera) {
  const colmap::Model in = colmap::read_model(kFox / "sparse/0");
  const colmap::Model out = colmap::read_model(dir_ / "out/sparse");
  ASSERT_EQ(in.cameras.size(), 1u);
  const colmap::Camera ours = undistort_camera(in.cameras.begin()->second);
  const colmap::Camera& theirs = out.cameras.begin()->second;
  std::cout << "colmap: " << theirs.width << "x" << theirs.height << " params " << theirs.params[0] << " "
            << theirs.params[1] << " " << theirs.params[2] << " " << theirs.params[3] << "\n";
  EXPECT_EQ(ours.model, CameraModelId::Pinhole);
  EXPECT_EQ(ours.width, theirs.width);  // 530 x 946 from 540 x 960
  EXPECT_EQ(ours.height, theirs.height);
  ASSERT_EQ(ours.params.size(), 4u);
  // Same doubles through the same arithmetic: equal to the last bit or two.
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(ours.params[i], theirs.params[i], 1e-12 * theirs.params[i]) << i;
}

TEST_F(ColmapUndistorter, MovesEveryKeypointWhereColmapDoes) {
  const colmap::Model in = colmap::read_model(kFox / "sparse/0");
  const colmap::Model out = colmap::read_model(dir_ / "out/sparse");
  const colmap::Camera& distorted = in.cameras.begin()->second;
  const colmap::Camera undistorted = undistort_camera(distorted);
  double max_err = 0;
  size_t n = 0;
  for (const auto& [id, image] : in.images) {
    const auto& moved = out.images.at(id).points2d;
    ASSERT_EQ(moved.size(), image.points2d.size());
    for (size_t k = 0; k < moved.size(); ++k, ++n) {
      const Vec2 p = undistort_pixel(distorted, undistorted, {image.points2d[k].x, image.points2d[k].y});
      max_err = std::max({max_err, std::abs(p[0] - moved[k].x), std::abs(p[1] - moved[k].y)});
    }
  }
  std::cout << n << " keypoints, max difference to colmap " << max_err << " px\n";
  // COLMAP stops its Newton iteration once a step is below 1e-5 (normalized), which leaves
  // an error of ~1e-10 normalized ≈ 1e-7 px; we iterate to machine precision.
  EXPECT_LT(max_err, 1e-6);
}

TEST_F(ColmapUndistorter, ImagesMatchColmapsUndistortedJpegs) {
  const colmap::Model in = colmap::read_model(kFox / "sparse/0");
  const colmap::Camera& distorted = in.cameras.begin()->second;
  const colmap::Camera undistorted = undistort_camera(distorted);
  for (const auto& name : kSubset) {
    const FloatImage ours = undistort_image(read_image_rgb(kFox / "images" / name), distorted, undistorted);
    const FloatImage theirs = read_image_rgb(dir_ / "out/images" / name);
    ASSERT_EQ(ours.width, theirs.width);
    ASSERT_EQ(ours.height, theirs.height);
    const DiffStats inner = compare(ours, theirs, 2), all = compare(ours, theirs, 0);
    std::cout << name << ": mean " << inner.mean * 255 << "/255, p99 " << inner.p99 * 255 << "/255, max "
              << inner.max * 255 << "/255 (with border: mean " << all.mean * 255 << ", p99 " << all.p99 * 255
              << ", max " << all.max * 255 << ")\n";
    const Registration reg = register_images(ours, theirs);
    std::cout << "  misregistration: shift (" << reg.tx << ", " << reg.ty << ") px, scale terms at the border ("
              << reg.edge_x << ", " << reg.edge_y << ") px\n";
    // Geometry: measured |t| ≤ 0.006 px and border terms ≤ 0.005 px; the fit recovers a
    // deliberate 0.1 px principal-point shift as 0.107 px and a 0.05% focal-length change
    // as 0.14 / 0.25 px at the border, so 0.02 px separates the two clearly.
    EXPECT_LT(std::abs(reg.tx), 0.02);
    EXPECT_LT(std::abs(reg.ty), 0.02);
    EXPECT_LT(std::abs(reg.edge_x), 0.02);
    EXPECT_LT(std::abs(reg.edge_y), 0.02);
    // Intensities: COLMAP warps at the source size (540x960) with a rescaled camera, rounds
    // to 8 bit, resizes to 530x946 with FreeImage's bilinear filter and writes a quality-100
    // 4:2:0 JPEG; we remap once, straight to 530x946. Measured (inner pixels): mean
    // 1.42–1.62/255, p99 5.9–7.8/255. Of that, the JPEG alone is ~0.65/255 mean, 2.4/255 p99
    // (re-encoding an image the same way), and emulating COLMAP's two resamplings with
    // OpenCV brings the rest to ~1.22/255 mean, 4.5/255 p99. The bounds leave ~25% margin;
    // the geometric check above is the sharp one.
    EXPECT_LT(inner.mean, 2.0 / 255);
    EXPECT_LT(inner.p99, 10.0 / 255);
  }
}

TEST(Undistort, PinholeCamerasPassThroughUntouched) {
  const colmap::Camera simple{1, CameraModelId::SimplePinhole, 40, 30, {50, 20, 15}};
  const colmap::Camera pinhole = undistort_camera(simple);
  EXPECT_EQ(pinhole.model, CameraModelId::Pinhole);
  EXPECT_EQ(pinhole.params, (std::vector<double>{50, 50, 20, 15}));
  EXPECT_EQ(pinhole.width, 40u);
  EXPECT_EQ(pinhole.height, 30u);
  FloatImage img{40, 30, 3, std::vector<float>(40 * 30 * 3)};
  std::mt19937 rng(3);
  for (float& v : img.pixels) v = std::uniform_real_distribution<float>(0, 1)(rng);
  const FloatImage out = undistort_image(img, simple, pinhole);
  EXPECT_EQ(out.pixels, img.pixels);  // bit for bit: no resampling
}

// A photo of a smooth pattern painted on the camera plane, taken through a distorted lens,
// undistorted, must show the same pattern through the pinhole camera: this pins down the
// direction of the warp and the half-pixel conventions on both sides of cv::remap.
TEST(Undistort, WarpsAnAnalyticPatternOntoThePinholeImage) {
  const auto pattern = [](Vec2 uv) {
    return float(0.5 + 0.25 * std::sin(7 * uv[0] + 1) + 0.2 * std::cos(5 * uv[1] - 2 * uv[0]));
  };
  for (const colmap::Camera& lens :
       {colmap::Camera{1, CameraModelId::OpenCV, 300, 200, {260, 250, 152, 97, -0.2, 0.05, 0.002, -0.003}},
        colmap::Camera{2, CameraModelId::OpenCVFisheye, 300, 200, {150, 150, 149, 101, 0.05, -0.02, 0.01, 0}}}) {
    FloatImage photo{300, 200, 3, std::vector<float>(300 * 200 * 3)};
    for (int y = 0; y < 200; ++y)
      for (int x = 0; x < 300; ++x)
        for (int c = 0; c < 3; ++c)
          photo.pixels[(size_t(y) * 300 + x) * 3 + c] = pattern(camera_from_image(lens, {x + 0.5, y + 0.5}));
    const colmap::Camera pinhole = undistort_camera(lens);
    const FloatImage out = undistort_image(photo, lens, pinhole);
    ASSERT_EQ(uint64_t(out.width), pinhole.width);
    double max_err = 0;
    for (int y = 2; y < out.height - 2; ++y)
      for (int x = 2; x < out.width - 2; ++x) {
        const Vec2 uv{(x + 0.5 - pinhole.params[2]) / pinhole.params[0],
                      (y + 0.5 - pinhole.params[3]) / pinhole.params[1]};
        max_err = std::max(max_err, double(std::abs(out.pixels[(size_t(y) * out.width + x) * 3] - pattern(uv))));
      }
    // Bilinear interpolation error of this pattern (≤ 0.01 per px² of curvature) plus
    // OpenCV's 1/32-px weights; a half-pixel shift would give errors above 0.03.
    EXPECT_LT(max_err, 0.006) << colmap::camera_model_info(lens.model).name;
  }
}

TEST(Undistort, RejectsMismatchedInput) {
  const colmap::Camera lens{1, CameraModelId::SimpleRadial, 40, 30, {50, 20, 15, 0.1}};
  const FloatImage wrong{41, 30, 3, std::vector<float>(41 * 30 * 3)};
  EXPECT_THROW(undistort_image(wrong, lens, undistort_camera(lens)), std::invalid_argument);
  const FloatImage right{40, 30, 3, std::vector<float>(40 * 30 * 3)};
  EXPECT_THROW(undistort_image(right, lens, lens), std::invalid_argument);  // target not PINHOLE
  EXPECT_THROW(undistort_camera(lens, UndistortOptions{2, 0.2, 2}), std::invalid_argument);
  EXPECT_THROW(undistort_camera(lens, UndistortOptions{0, 3, 2}), std::invalid_argument);
}
