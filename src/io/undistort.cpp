// Undistortion as COLMAP's image_undistorter does it: the choice of the pinhole camera
// follows COLMAP 3.8's UndistortCamera; the resampling uses OpenCV.
#include "desplat/io/undistort.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "io/opencv_reference.hpp"

namespace desplat {
namespace {

void check_options(const UndistortOptions& o) {
  if (!(o.blank_pixels >= 0 && o.blank_pixels <= 1))
    throw std::invalid_argument("undistort: blank_pixels must be in [0, 1], got " + std::to_string(o.blank_pixels));
  if (!(o.min_scale > 0 && o.min_scale <= o.max_scale && std::isfinite(o.max_scale)))
    throw std::invalid_argument("undistort: need 0 < min_scale <= max_scale, got " + std::to_string(o.min_scale) +
                                ", " + std::to_string(o.max_scale));
}

// Extremes of one coordinate of the undistorted positions of a border of the image.
struct Range {
  double lo = std::numeric_limits<double>::max();
  double hi = std::numeric_limits<double>::lowest();
  void add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

struct BorderRanges {
  Range left_x, right_x, top_y, bottom_y;
};

// Walks the pixel centers along the four borders of the distorted image (as COLMAP does)
// and records where they land under the undistorted pinhole `K`.
BorderRanges border_ranges(const colmap::Camera& distorted, const PinholeIntrinsics& K) {
  const auto to_pinhole = [&](Vec2 xy) {
    const Vec2 uv = camera_from_image(distorted, xy);
    return Vec2{K.fx * uv[0] + K.cx, K.fy * uv[1] + K.cy};
  };
  const double w = static_cast<double>(distorted.width), h = static_cast<double>(distorted.height);
  BorderRanges r;
  for (uint64_t y = 0; y < distorted.height; ++y) {
    const double yc = static_cast<double>(y) + 0.5;
    r.left_x.add(to_pinhole({0.5, yc})[0]);
    r.right_x.add(to_pinhole({w - 0.5, yc})[0]);
  }
  for (uint64_t x = 0; x < distorted.width; ++x) {
    const double xc = static_cast<double>(x) + 0.5;
    r.top_y.add(to_pinhole({xc, 0.5})[1]);
    r.bottom_y.add(to_pinhole({xc, h - 0.5})[1]);
  }
  return r;
}

// COLMAP's per-axis scale: from the scale that keeps every source pixel (min) and the one
// that leaves no blank pixel (max), interpolated by blank_pixels and clipped.
// `c` is the principal point, `size` the image size along this axis.
double axis_scale(const Range& low_side, const Range& high_side, double c, double size, const UndistortOptions& o) {
  const double keep_all = std::min(c / (c - low_side.lo), (size - 0.5 - c) / (high_side.hi - c));
  const double no_blank = std::max(c / (c - low_side.hi), (size - 0.5 - c) / (high_side.lo - c));
  const double scale = 1.0 / (keep_all * o.blank_pixels + no_blank * (1.0 - o.blank_pixels));
  if (!std::isfinite(scale))
    throw std::invalid_argument("undistort: the lens model cannot be undistorted at the image border");
  return std::clamp(scale, o.min_scale, o.max_scale);
}

cv::Mat wrap(const FloatImage& image) {
  return cv::Mat(image.height, image.width, CV_32FC(image.channels), const_cast<float*>(image.pixels.data()));
}

void check_image(const FloatImage& image, const char* who) {
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0 || image.channels > 4 ||
      image.pixels.size() != size_t(image.width) * image.height * image.channels)
    throw std::invalid_argument(std::string(who) + ": the pixel buffer does not match the image size");
}

FloatImage from_mat(const cv::Mat& m) {
  FloatImage out{m.cols, m.rows, m.channels(), std::vector<float>(m.total() * m.channels())};
  cv::Mat view(m.rows, m.cols, m.type(), out.pixels.data());
  m.copyTo(view);
  return out;
}

}  // namespace

colmap::Camera undistort_camera(const colmap::Camera& distorted, const UndistortOptions& options) {
  check_options(options);
  const PinholeIntrinsics K = pinhole_intrinsics(distorted);
  colmap::Camera out{
      distorted.id, colmap::CameraModelId::Pinhole, distorted.width, distorted.height, {K.fx, K.fy, K.cx, K.cy}};
  if (!camera_model_math(distorted.model).has_distortion) return out;

  const BorderRanges r = border_ranges(distorted, K);
  const double w = static_cast<double>(distorted.width), h = static_cast<double>(distorted.height);
  const double sx = axis_scale(r.left_x, r.right_x, K.cx, w, options);
  const double sy = axis_scale(r.top_y, r.bottom_y, K.cy, h, options);
  out.width = static_cast<uint64_t>(std::max(1.0, sx * w));  // truncated, as COLMAP
  out.height = static_cast<uint64_t>(std::max(1.0, sy * h));
  out.params[2] = K.cx * static_cast<double>(out.width) / w;
  out.params[3] = K.cy * static_cast<double>(out.height) / h;
  return out;
}

Vec2 undistort_pixel(const colmap::Camera& distorted, const colmap::Camera& undistorted, Vec2 xy) {
  return image_from_camera(undistorted, camera_from_image(distorted, xy));
}

FloatImage undistort_image(const FloatImage& image, const colmap::Camera& distorted,
                           const colmap::Camera& undistorted) {
  check_image(image, "undistort_image");
  if (static_cast<uint64_t>(image.width) != distorted.width || static_cast<uint64_t>(image.height) != distorted.height)
    throw std::invalid_argument("undistort_image: image is " + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + " px but camera " + std::to_string(distorted.id) +
                                " is " + std::to_string(distorted.width) + "x" + std::to_string(distorted.height));
  if (undistorted.model != colmap::CameraModelId::Pinhole || undistorted.params.size() != 4 || undistorted.width == 0 ||
      undistorted.height == 0)
    throw std::invalid_argument("undistort_image: the target camera must be a PINHOLE camera with a size");
  const PinholeIntrinsics K = pinhole_intrinsics(undistorted);
  const PinholeIntrinsics K_src = pinhole_intrinsics(distorted);
  const bool identity = !camera_model_math(distorted.model).has_distortion && undistorted.width == distorted.width &&
                        undistorted.height == distorted.height && K.fx == K_src.fx && K.fy == K_src.fy &&
                        K.cx == K_src.cx && K.cy == K_src.cy;
  if (identity) return image;

  // cv::remap samples source pixel (i, j) at integer coordinates: COLMAP position − 0.5.
  const int W = static_cast<int>(undistorted.width), H = static_cast<int>(undistorted.height);
  const double src_w = image.width, src_h = image.height;
  const CameraModelMath& math = camera_model_math(distorted.model);
  cv::Mat map_x(H, W, CV_32F), map_y(H, W, CV_32F);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    float* mx = map_x.ptr<float>(y);
    float* my = map_y.ptr<float>(y);
    for (int x = 0; x < W; ++x) {
      const Vec2 uv{(x + 0.5 - K.cx) / K.fx, (y + 0.5 - K.cy) / K.fy};
      const Vec2 s = math.image_from_camera(distorted.params.data(), uv);
      const double sx = s[0] - 0.5, sy = s[1] - 0.5;
      const bool inside = sx >= -0.5 && sx <= src_w - 0.5 && sy >= -0.5 && sy <= src_h - 0.5;  // false for NaN
      // Inside the photo's area: clamp so the outer half pixel repeats the border pixel.
      mx[x] = inside ? static_cast<float>(std::clamp(sx, 0.0, src_w - 1)) : -2.0f;
      my[x] = inside ? static_cast<float>(std::clamp(sy, 0.0, src_h - 1)) : -2.0f;
    }
  }
  cv::Mat out;
  cv::remap(wrap(image), out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return from_mat(out);
}

FloatImage resize_area(const FloatImage& image, int width, int height) {
  check_image(image, "resize_area");
  if (width <= 0 || height <= 0)
    throw std::invalid_argument("resize_area: target size must be positive, got " + std::to_string(width) + "x" +
                                std::to_string(height));
  if (width == image.width && height == image.height) return image;
  cv::Mat out;
  cv::resize(wrap(image), out, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  return from_mat(out);
}

namespace detail {

std::vector<Vec2> opencv_project_points(const colmap::Camera& camera,
                                        const std::vector<std::array<double, 3>>& points_cam) {
  using colmap::CameraModelId;
  const PinholeIntrinsics K = pinhole_intrinsics(camera);
  const cv::Matx33d Kmat(K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  const std::vector<double> dist(camera.params.begin() + 4, camera.params.end());
  std::vector<cv::Point3d> in;
  for (const auto& p : points_cam) in.emplace_back(p[0], p[1], p[2]);
  std::vector<cv::Point2d> out;
  const cv::Vec3d zero(0, 0, 0);
  if (camera.model == CameraModelId::OpenCV || camera.model == CameraModelId::FullOpenCV)
    cv::projectPoints(in, zero, zero, Kmat, dist, out);
  else if (camera.model == CameraModelId::OpenCVFisheye)
    cv::fisheye::projectPoints(in, out, zero, zero, Kmat, dist);
  else
    throw std::invalid_argument("opencv_project_points: OpenCV has no model matching camera " +
                                std::to_string(camera.id));
  std::vector<Vec2> result;
  for (const auto& p : out) result.push_back({p.x, p.y});
  return result;
}

}  // namespace detail
}  // namespace desplat
