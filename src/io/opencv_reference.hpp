// OpenCV's own lens projection, for tests that check our camera-model table against an
// independent implementation. Lives in the library only because the tests do not see
// OpenCV's headers (desplat links OpenCV privately); not part of the public API.
#pragma once

#include <array>
#include <vector>

#include "desplat/io/camera_models.hpp"
#include "desplat/io/colmap.hpp"

namespace desplat::detail {

// Pixel positions of camera-space points (x, y, z with z > 0) under `camera`, computed by
// cv::projectPoints (OPENCV, FULL_OPENCV: the same coefficient order as COLMAP) or
// cv::fisheye::projectPoints (OPENCV_FISHEYE), with zero rotation and translation.
// OpenCV puts pixel centers at integers, COLMAP at +0.5; the formula u = fx·x'' + cx is the
// same, so the returned numbers compare directly with image_from_camera.
// Throws std::invalid_argument for any other model.
std::vector<Vec2> opencv_project_points(const colmap::Camera& camera,
                                        const std::vector<std::array<double, 3>>& points_cam);

}  // namespace desplat::detail
