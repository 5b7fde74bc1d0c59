// COLMAP camera-model table (camera_models.hpp) against independent expectations:
//   * OpenCV's own projection (cv::projectPoints, cv::fisheye::projectPoints) for the models
//     OpenCV has — OPENCV, FULL_OPENCV, OPENCV_FISHEYE — and for the COLMAP models that are
//     special cases of them (SIMPLE_RADIAL, RADIAL, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE,
//     THIN_PRISM_FISHEYE without its tangential/prism terms);
//   * the published closed forms, written out in this file, for what OpenCV lacks (FOV,
//     thin-prism tangential and prism terms);
//   * project/unproject round trips for every model;
//   * the parameter layout of colmap::camera_model_info.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "desplat/io/camera_models.hpp"
#include "io/opencv_reference.hpp"

using namespace desplat;
using colmap::CameraModelId;

namespace {

colmap::Camera make(CameraModelId model, std::vector<double> params, uint64_t w = 640, uint64_t h = 480) {
  return colmap::Camera{7, model, w, h, std::move(params)};
}

// Realistic lenses, one per model (ids 0–10), with every coefficient non-zero.
std::vector<colmap::Camera> every_model() {
  return {
      make(CameraModelId::SimplePinhole, {500, 320, 240}),
      make(CameraModelId::Pinhole, {500, 510, 321, 239}),
      make(CameraModelId::SimpleRadial, {500, 320, 240, -0.08}),
      make(CameraModelId::Radial, {500, 320, 240, -0.08, 0.02}),
      make(CameraModelId::OpenCV, {500, 510, 321, 239, -0.1, 0.03, 0.001, -0.002}),
      make(CameraModelId::OpenCVFisheye, {300, 305, 321, 239, 0.05, -0.01, 0.003, -0.001}),
      make(CameraModelId::FullOpenCV, {500, 510, 321, 239, -0.1, 0.03, 0.001, -0.002, 0.004, 0.01, 0.002, 0.001}),
      make(CameraModelId::FOV, {400, 405, 321, 239, 0.9}),
      make(CameraModelId::SimpleRadialFisheye, {300, 320, 240, 0.04}),
      make(CameraModelId::RadialFisheye, {300, 320, 240, 0.04, -0.01}),
      make(CameraModelId::ThinPrismFisheye,
           {300, 305, 321, 239, 0.05, -0.01, 0.001, -0.002, 0.003, -0.001, 0.0005, -0.0007}),
  };
}

bool is_fisheye(CameraModelId id) {
  return id == CameraModelId::OpenCVFisheye || id == CameraModelId::SimpleRadialFisheye ||
         id == CameraModelId::RadialFisheye || id == CameraModelId::ThinPrismFisheye;
}

// Camera-plane points on a grid inside the lens's well-behaved region.
std::vector<Vec2> plane_grid(double extent) {
  std::vector<Vec2> pts;
  for (int i = -6; i <= 6; ++i)
    for (int j = -6; j <= 6; ++j) pts.push_back({extent * i / 6.0, extent * j / 6.0 * 0.8});
  pts.push_back({1e-9, -2e-9});  // next to the axis, where fisheye models switch branches
  return pts;
}

std::vector<std::array<double, 3>> random_points(int n, double spread, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-spread, spread), z(0.5, 4);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < n; ++i) {
    const double depth = z(rng);
    pts.push_back({u(rng) * depth, u(rng) * depth, depth});
  }
  return pts;
}

// Our projection of camera-space points vs OpenCV's for `reference` (an OpenCV-type lens).
void expect_matches_opencv(const colmap::Camera& ours, const colmap::Camera& reference, double spread) {
  const auto pts = random_points(200, spread, 11);
  const std::vector<Vec2> cv = detail::opencv_project_points(reference, pts);
  ASSERT_EQ(cv.size(), pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const Vec2 px = image_from_camera(ours, {pts[i][0] / pts[i][2], pts[i][1] / pts[i][2]});
    // Double precision on both sides; 1e-9 px is ~1e-12 relative to the coordinates.
    EXPECT_NEAR(px[0], cv[i][0], 1e-9) << colmap::camera_model_info(ours.model).name << " point " << i;
    EXPECT_NEAR(px[1], cv[i][1], 1e-9) << colmap::camera_model_info(ours.model).name << " point " << i;
  }
}

}  // namespace

TEST(CameraModels, TableCoversEveryColmapModelWithItsParameterLayout) {
  for (const auto& info : colmap::camera_models()) {
    const CameraModelMath& math = camera_model_math(info.id);
    EXPECT_EQ(math.id, info.id);
    // The parameter list in colmap.hpp starts "f, cx, cy" or "fx, fy, cx, cy".
    const std::string names = info.param_names;
    EXPECT_EQ(math.num_focal, names.rfind("f,", 0) == 0 ? 1 : 2) << info.name;
    EXPECT_EQ(math.has_distortion, info.num_params > 3 + (math.num_focal - 1)) << info.name;
  }
  EXPECT_EQ(colmap::camera_models().size(), 11u);
  EXPECT_THROW(camera_model_math(static_cast<CameraModelId>(11)), std::invalid_argument);
  EXPECT_THROW(image_from_camera(make(CameraModelId::OpenCV, {1, 2, 3}), {0, 0}), std::invalid_argument);
}

TEST(CameraModels, ProjectThenUnprojectIsTheIdentityForEveryModel) {
  const auto cams = every_model();
  ASSERT_EQ(cams.size(), 11u);
  for (const auto& cam : cams) {
    const double extent = is_fisheye(cam.model) ? 2.0 : 0.7;  // fisheyes: up to ~63° off axis
    for (const Vec2& uv : plane_grid(extent)) {
      const Vec2 back = camera_from_image(cam, image_from_camera(cam, uv));
      EXPECT_NEAR(back[0], uv[0], 1e-10 * (1 + std::abs(uv[0]))) << colmap::camera_model_info(cam.model).name;
      EXPECT_NEAR(back[1], uv[1], 1e-10 * (1 + std::abs(uv[1]))) << colmap::camera_model_info(cam.model).name;
    }
  }
}

TEST(CameraModels, UnprojectThenProjectIsTheIdentityOnEveryPixelOfTheImage) {
  for (const auto& cam : every_model()) {
    for (double y = 0.5; y < 480; y += 37.3)
      for (double x = 0.5; x < 640; x += 41.1) {
        const Vec2 px = image_from_camera(cam, camera_from_image(cam, {x, y}));
        EXPECT_NEAR(px[0], x, 1e-8) << colmap::camera_model_info(cam.model).name;
        EXPECT_NEAR(px[1], y, 1e-8) << colmap::camera_model_info(cam.model).name;
      }
  }
}

TEST(CameraModels, OpenCVModelsMatchCvProjectPoints) {
  const auto cams = every_model();
  expect_matches_opencv(cams[4], cams[4], 0.6);  // OPENCV
  expect_matches_opencv(cams[6], cams[6], 0.6);  // FULL_OPENCV
  expect_matches_opencv(cams[5], cams[5], 1.5);  // OPENCV_FISHEYE, up to ~56° off axis
}

TEST(CameraModels, SpecialCasesOfOpenCVModelsMatchOpenCV) {
  const double f = 500, cx = 320, cy = 240;
  expect_matches_opencv(make(CameraModelId::SimpleRadial, {f, cx, cy, -0.08}),
                        make(CameraModelId::OpenCV, {f, f, cx, cy, -0.08, 0, 0, 0}), 0.6);
  expect_matches_opencv(make(CameraModelId::Radial, {f, cx, cy, -0.08, 0.02}),
                        make(CameraModelId::OpenCV, {f, f, cx, cy, -0.08, 0.02, 0, 0}), 0.6);
  expect_matches_opencv(make(CameraModelId::SimpleRadialFisheye, {f, cx, cy, 0.04}),
                        make(CameraModelId::OpenCVFisheye, {f, f, cx, cy, 0.04, 0, 0, 0}), 1.5);
  expect_matches_opencv(make(CameraModelId::RadialFisheye, {f, cx, cy, 0.04, -0.01}),
                        make(CameraModelId::OpenCVFisheye, {f, f, cx, cy, 0.04, -0.01, 0, 0}), 1.5);
  // Thin prism without tangential and prism terms is the equidistant fisheye with k1..k4.
  expect_matches_opencv(make(CameraModelId::ThinPrismFisheye, {f, 505, cx, cy, 0.05, -0.01, 0, 0, 0.003, -0.001, 0, 0}),
                        make(CameraModelId::OpenCVFisheye, {f, 505, cx, cy, 0.05, -0.01, 0.003, -0.001}), 1.5);
}

TEST(CameraModels, ThinPrismTangentialAndPrismTermsFollowTheirFormula) {
  const auto cam = every_model()[10];
  const double* p = cam.params.data();
  for (const Vec2& uv : plane_grid(1.5)) {
    // Equidistant point, then radial + tangential + thin prism (Weng et al.).
    const double r = std::hypot(uv[0], uv[1]);
    const double s = r > 1e-12 ? std::atan(r) / r : 1;
    const double x = uv[0] * s, y = uv[1] * s, r2 = x * x + y * y;
    const double radial = 1 + p[4] * r2 + p[5] * r2 * r2 + p[8] * std::pow(r2, 3) + p[9] * std::pow(r2, 4);
    const double xd = x * radial + 2 * p[6] * x * y + p[7] * (r2 + 2 * x * x) + p[10] * r2;
    const double yd = y * radial + 2 * p[7] * x * y + p[6] * (r2 + 2 * y * y) + p[11] * r2;
    const Vec2 px = image_from_camera(cam, uv);
    EXPECT_NEAR(px[0], p[0] * xd + p[2], 1e-9);
    EXPECT_NEAR(px[1], p[1] * yd + p[3], 1e-9);
  }
}

TEST(CameraModels, FovModelFollowsDevernayFaugeras) {
  const auto cam = every_model()[7];
  const double omega = cam.params[4];
  for (const Vec2& uv : plane_grid(0.7)) {
    const double r = std::hypot(uv[0], uv[1]);
    // r_d = atan(2·r·tan(ω/2)) / ω; its limit at r = 0 is 2·tan(ω/2)/ω.
    const double factor =
        r > 0 ? std::atan(2 * r * std::tan(omega / 2)) / (omega * r) : 2 * std::tan(omega / 2) / omega;
    const Vec2 px = image_from_camera(cam, uv);
    // COLMAP's Taylor branch for r² < 1e-4 is accurate to O(r⁴) ≈ 1e-8 relative there.
    const double tol = r * r < 1e-4 ? 1e-5 : 1e-9;
    EXPECT_NEAR(px[0], cam.params[0] * uv[0] * factor + cam.params[2], tol);
    EXPECT_NEAR(px[1], cam.params[1] * uv[1] * factor + cam.params[3], tol);
  }
}

TEST(CameraModels, RescaleFollowsColmapCameraRescale) {
  const auto fox = make(CameraModelId::OpenCV, {687.8, 687.3, 270, 480, 0.0561, -0.0777, -0.0017, -0.0025}, 540, 960);
  const auto half = rescale_camera(fox, 270, 480);
  EXPECT_EQ(half.width, 270u);
  EXPECT_EQ(half.height, 480u);
  const std::vector<double> expected{343.9, 343.65, 135, 240, 0.0561, -0.0777, -0.0017, -0.0025};
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_DOUBLE_EQ(half.params[i], expected[i]) << i;
  // One focal length: scaled by the mean of the two axis factors.
  const auto radial = rescale_camera(make(CameraModelId::SimpleRadial, {100, 50, 40, 0.1}, 100, 80), 50, 20);
  EXPECT_DOUBLE_EQ(radial.params[0], 100 * (0.5 + 0.25) / 2);
  EXPECT_DOUBLE_EQ(radial.params[1], 25);
  EXPECT_DOUBLE_EQ(radial.params[2], 10);
  // A resized image sees the same camera-plane point at the scaled pixel position.
  const Vec2 uv{0.2, -0.3};
  const Vec2 a = image_from_camera(fox, uv), b = image_from_camera(half, uv);
  EXPECT_NEAR(b[0], a[0] / 2, 1e-12);
  EXPECT_NEAR(b[1], a[1] / 2, 1e-12);
  EXPECT_THROW(rescale_camera(fox, 0, 10), std::invalid_argument);
}
