// Transient sparse points (docs/METHOD.md §5, transient points).
#include "desplat/train/transient_points.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "desplat/train/effects.hpp"

namespace desplat {

std::string to_string(TransientPointAction action) {
  switch (action) {
    case TransientPointAction::keep:
      return "keep";
    case TransientPointAction::drop:
      return "drop";
    case TransientPointAction::seed:
      return "seed";
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

// Mean |image − min(1, gain · rgb)| over RGB at the pixel x projects into, or a negative value
// when x is behind the camera, projects outside the image or onto a pixel the user's mask ignores.
float color_difference(const TrainView& view, const std::array<float, 3>& x, const std::array<uint8_t, 3>& rgb,
                       const std::array<float, 3>& gain) {
  const long long pixel = view.camera.pixel_of(x);
  if (pixel < 0) return -1.0f;
  if (!view.keep.empty() && view.keep[size_t(pixel)] == 0) return -1.0f;  // ignored by the user: no evidence
  float diff = 0;
  for (int k = 0; k < 3; ++k) {
    const float expected = std::min(1.0f, gain[k] * (rgb[k] / 255.0f));  // photos saturate at 1
    diff += std::abs(byte_to_float(view.image.pixels[3 * size_t(pixel) + k]) - expected);
  }
  return diff / 3.0f;
}

}  // namespace

std::vector<uint8_t> transient_points(const TrainingData& data, const TransientPointSettings& s, Communicator* comm) {
  const size_t n = data.points.size();
  std::vector<uint8_t> transient(n, 0);
  if (data.point_track_images.empty() && data.point_train_views.empty()) return transient;
  if (data.point_track_images.size() != n || data.point_train_views.size() != n || data.colors.size() != n)
    throw std::invalid_argument("transient_points: track information does not match the points");
  for (const std::vector<int32_t>& views : data.point_train_views)
    for (const int32_t v : views)
      if (v < 0 || size_t(v) >= data.train.size())
        throw std::invalid_argument("transient_points: a track names a training view that does not exist");
  const std::vector<std::array<float, 3>> gains =
      s.per_view_gain ? view_gains(data, {}, comm)
                      : std::vector<std::array<float, 3>>(data.train.size(), {1.0f, 1.0f, 1.0f});
  // Each view's colour evidence on the rank holding its photo; a point any view disagrees
  // with is transient.
  const int rank = comm ? comm->rank() : 0, ranks = comm ? comm->size() : 1;
  for (size_t i = 0; i < n; ++i) {
    if (int64_t(data.point_track_images[i]) < s.min_track_images) {
      transient[i] = rank == 0;  // counted once in the sum over ranks
      continue;
    }
    for (const int32_t v : data.point_train_views[i]) {
      if (rank_of_view(size_t(v), ranks) != rank) continue;
      if (color_difference(data.train[v], data.points[i], data.colors[i], gains[size_t(v)]) > s.color_tolerance) {
        transient[i] = 1;
        break;
      }
    }
  }
  if (comm) {
    std::vector<int64_t> votes(transient.begin(), transient.end());
    comm->sum(std::span(votes));
    for (size_t i = 0; i < n; ++i) transient[i] = votes[i] > 0;
  }
  return transient;
}

}  // namespace desplat
