// Ordered frames or an unordered collection, from thumbnails; see include/desplat/sfm/sfm.hpp
// ("Ordered frames or an unordered collection").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "desplat/core/statistics.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/sfm/sfm.hpp"

namespace desplat::sfm {

std::vector<float> order_thumbnail(const FloatImage& image) {
  constexpr int S = kOrderThumbnailSize, kPlane = S * S;
  std::vector<float> out(kOrderThumbnailValues, 0.0f);
  const int C = image.channels;
  if (image.width <= 0 || image.height <= 0 || C <= 0) return out;
  // Cell (cx, cy) averages the pixels [cx·W/S, (cx+1)·W/S) × (the same in y), at least one
  // pixel each, so an image smaller than S px still fills every cell.
  const auto span = [](int cell, int size) {
    const int lo = std::min(cell * size / S, size - 1);
    return std::pair{lo, std::max(lo + 1, (cell + 1) * size / S)};
  };
  for (int ch = 0; ch < 3; ++ch) {
    const int c = std::min(ch, C - 1);  // grey photos: the one channel thrice
    std::vector<double> v(kPlane, 0.0);
    double mean = 0;
    for (int cy = 0; cy < S; ++cy) {
      const auto [y0, y1] = span(cy, image.height);
      for (int cx = 0; cx < S; ++cx) {
        const auto [x0, x1] = span(cx, image.width);
        double sum = 0;
        for (int y = y0; y < y1; ++y)
          for (int x = x0; x < x1; ++x) sum += image.pixels[(size_t(y) * image.width + x) * C + c];
        v[cy * S + cx] = sum / (double(y1 - y0) * (x1 - x0));
        mean += v[cy * S + cx] / kPlane;
      }
    }
    double var = 0;
    for (double x : v) var += (x - mean) * (x - mean) / kPlane;
    if (!(var > 1e-12)) continue;  // a flat channel carries no view to compare: zeros
    const double inv_sd = 1.0 / std::sqrt(var);
    for (int i = 0; i < kPlane; ++i) out[ch * kPlane + i] = static_cast<float>((v[i] - mean) * inv_sd);
  }
  return out;
}

namespace {

// The RMS difference of two thumbnails over the cells they share when `b` is moved by
// (dx, dy) cells.
double shifted_rms_difference(const std::vector<float>& a, const std::vector<float>& b, int dx, int dy) {
  constexpr int S = kOrderThumbnailSize;
  double sum = 0;
  int values = 0;
  for (int ch = 0; ch < 3; ++ch)
    for (int y = std::max(0, dy); y < std::min(S, S + dy); ++y)
      for (int x = std::max(0, dx); x < std::min(S, S + dx); ++x) {
        const double d = double(a[(ch * S + y) * S + x]) - double(b[(ch * S + y - dy) * S + (x - dx)]);
        sum += d * d;
        ++values;
      }
  return std::sqrt(sum / std::max(1, values));
}

// A camera that moved a little between two photos sees the same content moved across the frame,
// so the best match over shifts of up to kOrderMaxShift cells is taken.
double thumbnail_distance(const std::vector<float>& a, const std::vector<float>& b) {
  double best = shifted_rms_difference(a, b, 0, 0);
  for (int dy = -kOrderMaxShift; dy <= kOrderMaxShift; ++dy)
    for (int dx = -kOrderMaxShift; dx <= kOrderMaxShift; ++dx)
      best = std::min(best, shifted_rms_difference(a, b, dx, dy));
  return best;
}

}  // namespace

CaptureOrder judge_capture_order(const std::vector<std::vector<float>>& thumbnails) {
  const size_t n = thumbnails.size();
  for (const std::vector<float>& t : thumbnails)
    if (t.size() != size_t(kOrderThumbnailValues))
      throw std::invalid_argument("judge_capture_order: a thumbnail has " + std::to_string(t.size()) +
                                  " values, expected " + std::to_string(kOrderThumbnailValues) +
                                  " (order_thumbnail's)");
  CaptureOrder r;
  if (n < 4) {
    r.reason = "too few photos (" + std::to_string(n) + ") to tell whether they are in order";
    return r;
  }
  std::vector<double> neighbours, far;
  for (size_t i = 0; i + 1 < n; ++i) neighbours.push_back(thumbnail_distance(thumbnails[i], thumbnails[i + 1]));
  for (size_t i = 0; i + n / 2 < n; ++i) far.push_back(thumbnail_distance(thumbnails[i], thumbnails[i + n / 2]));
  r.neighbour_distance = median(neighbours);
  r.far_distance = median(far);
  r.ordered = r.far_distance > 0 && r.neighbour_distance <= kOrderedDistanceRatio * r.far_distance;
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "photos next to each other in file-name order differ by %.3f, photos half the capture apart by "
                "%.3f (ratio %.2f; in order below %.2f)",
                r.neighbour_distance, r.far_distance, r.far_distance > 0 ? r.neighbour_distance / r.far_distance : 1.0,
                kOrderedDistanceRatio);
  r.reason = std::string(r.ordered ? "taken in order: " : "not in file-name order: ") + buf;
  return r;
}

CaptureOrder detect_capture_order(const std::filesystem::path& dir, const std::vector<std::filesystem::path>& photos) {
  std::vector<std::vector<float>> thumbnails;
  thumbnails.reserve(photos.size());
  for (const auto& p : photos) {
    try {
      thumbnails.push_back(order_thumbnail(read_image_rgb(dir / p)));
    } catch (const ImageError&) {
      thumbnails.emplace_back(kOrderThumbnailValues, 0.0f);
    }
  }
  return judge_capture_order(thumbnails);
}

}  // namespace desplat::sfm
