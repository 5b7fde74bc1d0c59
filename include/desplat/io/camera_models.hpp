// The math of COLMAP's camera models (ids 0–10, SIMPLE_PINHOLE … THIN_PRISM_FISHEYE) as one
// table of small functions, keyed by colmap::CameraModelId (names and parameter lists are in
// colmap::camera_model_info).
//
// Frames and units (docs/METHOD.md §1, COLMAP convention):
//   * a camera-plane point is (u, v) = (x/z, y/z) of a point in camera space (x right, y down,
//     z forward); it is unitless.
//   * pixels: COLMAP's convention, the center of pixel (i, j) is at (i + 0.5, j + 0.5).
//   * `params` are a colmap::Camera's params: 1-focal models start f, cx, cy; 2-focal models
//     fx, fy, cx, cy; the distortion coefficients follow. Distortion is defined on the camera
//     plane, so it does not change when an image is resized; focal lengths and principal
//     point do (rescale_camera).
// Formulas are those of COLMAP 3.8's WorldToImage / ImageToWorld (src/base/camera_models.h;
// ImgFromCam / CamFromImg in later versions):
// radial/tangential polynomials, the equidistant fisheye family (θ = atan r), FOV's closed
// form, and the thin-prism fisheye's equidistant pre-mapping.
//
// All functions are pure and thread-safe. Functions taking a colmap::Camera throw
// std::invalid_argument when its params do not have the model's length.
#pragma once

#include <array>
#include <cstdint>

#include "desplat/io/colmap.hpp"

namespace desplat {

using Vec2 = std::array<double, 2>;

struct CameraModelMath {
  colmap::CameraModelId id;
  int num_focal;        // 1: params[0] = f; 2: params[0], params[1] = fx, fy
  bool has_distortion;  // false only for SIMPLE_PINHOLE and PINHOLE
  // Camera-plane point -> pixel, distortion applied. `params` has the model's length.
  Vec2 (*image_from_camera)(const double* params, Vec2 uv);
  // Pixel -> camera-plane point: the inverse of image_from_camera. Closed form for the
  // pinhole and FOV models; otherwise Newton's method on the distortion (as COLMAP's
  // IterativeUndistortion, ≤ 100 steps, central-difference Jacobian), which converges to
  // machine precision wherever the distortion is invertible. Where it is not (beyond the
  // radius at which a polynomial distortion folds back) the result is COLMAP's best effort too.
  Vec2 (*camera_from_image)(const double* params, Vec2 xy);
};

// The table row of a model; throws std::invalid_argument for an id outside 0–10.
const CameraModelMath& camera_model_math(colmap::CameraModelId id);

Vec2 image_from_camera(const colmap::Camera& camera, Vec2 uv);
Vec2 camera_from_image(const colmap::Camera& camera, Vec2 xy);

// Focal lengths and principal point [px]; fx == fy for 1-focal models.
struct PinholeIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
};
PinholeIntrinsics pinhole_intrinsics(const colmap::Camera& camera);

// The camera of the same lens for a resized image, as COLMAP's Camera::Rescale: with
// s_x = width / camera.width and s_y = height / camera.height, cx ·= s_x, cy ·= s_y,
// fx ·= s_x, fy ·= s_y (1-focal models: f ·= (s_x + s_y) / 2); distortion unchanged.
// Throws std::invalid_argument for a zero size.
colmap::Camera rescale_camera(const colmap::Camera& camera, uint64_t width, uint64_t height);

}  // namespace desplat
