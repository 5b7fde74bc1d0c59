// Transient sparse points (docs/METHOD.md §5, transient points).
#include "desplat/train/transient_points.hpp"

#include <cmath>
#include <stdexcept>

#include "desplat/train/trainer.hpp"

namespace desplat {

std::string to_string(TransientPointAction action) {
  switch (action) {
    case TransientPointAction::keep: return "keep";
    case TransientPointAction::drop: return "drop";
    case TransientPointAction::seed: return "seed";
  }
  return "keep";
}

TransientPointAction transient_point_action_from_string(const std::string& text) {
  if (text == "keep") return TransientPointAction::keep;
  if (text == "drop") return TransientPointAction::drop;
  if (text == "seed") return TransientPointAction::seed;
  throw std::invalid_argument("config: init.transient_points must be keep, drop or seed, not '" + text + "'");
}

namespace {

// Mean |image − rgb| over RGB at the pixel x projects into, or a negative value when x is
// behind the camera, projects outside the image or onto a pixel the user's mask ignores.
float color_difference(const TrainView& view, const std::array<float, 3>& x, const std::array<uint8_t, 3>& rgb) {
  const long long pixel = view.camera.pixel_of(x);
  if (pixel < 0) return -1.0f;
  if (!view.keep.empty() && view.keep[size_t(pixel)] == 0) return -1.0f;  // ignored by the user: no evidence
  float diff = 0;
  for (int k = 0; k < 3; ++k) diff += std::abs(byte_to_float(view.image.pixels[3 * size_t(pixel) + k]) - rgb[k] / 255.0f);
  return diff / 3.0f;
}

}  // namespace

std::vector<uint8_t> transient_points(const TrainingData& data, const TransientPointSettings& s) {
  const size_t n = data.points.size();
  std::vector<uint8_t> transient(n, 0);
  if (data.point_track_images.empty() && data.point_train_views.empty()) return transient;
  if (data.point_track_images.size() != n || data.point_train_views.size() != n || data.colors.size() != n)
    throw std::invalid_argument("transient_points: track information does not match the points");
  for (size_t i = 0; i < n; ++i) {
    if (int64_t(data.point_track_images[i]) < s.min_track_images) {
      transient[i] = 1;
      continue;
    }
    for (const int32_t v : data.point_train_views[i]) {
      if (v < 0 || size_t(v) >= data.train.size())
        throw std::invalid_argument("transient_points: a track names a training view that does not exist");
      if (color_difference(data.train[v], data.points[i], data.colors[i]) > s.color_tolerance) {
        transient[i] = 1;
        break;
      }
    }
  }
  return transient;
}

}  // namespace desplat
