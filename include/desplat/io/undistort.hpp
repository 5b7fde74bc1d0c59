// Undistortion of COLMAP cameras and photos to the pinhole model the rasterizer uses
// (docs/METHOD.md §1: distorted models are undistorted before training, as COLMAP's
// image_undistorter does).
//
// Pixels follow COLMAP's convention (pixel (i, j) has its center at (i + 0.5, j + 0.5)).
// Thread-safe: no shared state.
#pragma once

#include "desplat/io/camera_models.hpp"
#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"

namespace desplat {

// The options of `colmap image_undistorter` that shape the camera, with its defaults.
// (Its region-of-interest options and max_image_size are not supported: they are off by
// default.)
struct UndistortOptions {
  double blank_pixels = 0;  // 0: no blank pixels in the result; 1: no source pixel lost
  double min_scale = 0.2;   // bounds of the size of the result relative to the input
  double max_scale = 2.0;
};

// The PINHOLE camera COLMAP 3.8's UndistortCamera chooses: the same focal lengths
// (f for both axes of 1-focal models); size scaled per axis by the factor that makes the
// distorted image's border (its pixel centers 0.5 px inside) just cover the result
// (blank_pixels 0) or just fit inside it (1), clipped to [min_scale, max_scale], truncated to
// whole pixels; principal point scaled with the size. SIMPLE_PINHOLE and PINHOLE cameras
// keep their size, focal lengths and principal point. The id is kept.
// Throws std::invalid_argument for bad options or a camera whose params do not fit its model.
colmap::Camera undistort_camera(const colmap::Camera& distorted, const UndistortOptions& options = {});

// Where a pixel position of the distorted image lands in the undistorted one (as COLMAP's
// UndistortReconstruction moves keypoints): distorted camera_from_image, then undistorted
// image_from_camera.
Vec2 undistort_pixel(const colmap::Camera& distorted, const colmap::Camera& undistorted, Vec2 xy);

// Resamples `image` (distorted.width × distorted.height) into undistorted.width ×
// undistorted.height: each output pixel center is projected into the distorted image and
// read with bilinear interpolation (cv::remap). Sources inside the photo's area (up to its
// outer pixel edges) are read with clamping at the border, sources outside it give black.
// (COLMAP also blacks the outermost half pixel, so the outermost output pixels can differ.)
// A SIMPLE_PINHOLE or PINHOLE `distorted` camera returns the image unchanged, without
// resampling. Throws std::invalid_argument when the image size disagrees with `distorted`
// or `undistorted` is not a PINHOLE camera.
FloatImage undistort_image(const FloatImage& image, const colmap::Camera& distorted, const colmap::Camera& undistorted);

// Resizes with OpenCV's INTER_AREA (pixel-area averaging when shrinking).
// Throws std::invalid_argument for a non-positive size or an inconsistent image.
FloatImage resize_area(const FloatImage& image, int width, int height);

}  // namespace desplat
