#include "desplat/train/effects.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "desplat/core/statistics.hpp"
#include "desplat/train/open_sky.hpp"

namespace desplat {

Effects Effects::parse(const std::string& text) {
  Effects e;
  if (text == "none") return e;
  std::stringstream list(text);
  std::string name;
  bool any = false;
  while (std::getline(list, name, ',')) {
    if (name == "distractors") {
      e.distractors = true;
    } else if (name == "appearance") {
      e.appearance = true;
    } else if (name == "auto") {
      throw std::invalid_argument("--effects: 'auto' stands alone (it chooses the whole set)");
    } else if (name == "background") {
      e.background = true;
    } else {
      throw std::invalid_argument("--effects: unknown effect '" + name +
                                  "' (none, or a comma-separated list of distractors, appearance, background)");
    }
    any = true;
  }
  if (!any)
    throw std::invalid_argument(
        "--effects is empty (none, or a comma-separated list of distractors, appearance, "
        "background)");
  return e;
}

Effects Effects::of(const TrainConfig& config) {
  return {config.distractors.enabled, config.appearance.enabled, config.background.enabled};
}

void Effects::apply(TrainConfig& config) const {
  config.distractors.enabled = distractors;
  config.appearance.enabled = appearance;
  config.background.enabled = background;
}

std::string Effects::to_string() const {
  std::string out;
  for (auto [on, name] : {std::pair{distractors, "distractors"}, std::pair{appearance, "appearance"},
                          std::pair{background, "background"}})
    if (on) {
      if (!out.empty()) out += ',';
      out += name;
    }
  return out.empty() ? "none" : out;
}

// --effects auto: the evidence (docs/METHOD.md §10, choosing the effects).
namespace {

// 1.4826 × the median absolute deviation: the standard deviation for normal data, robust to
// a few odd views.
double robust_spread(const std::vector<double>& v) {
  const double m = median(v);
  std::vector<double> dev;
  for (const double x : v) dev.push_back(std::abs(x - m));
  return 1.4826 * median(dev);
}

std::string fixed2(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", x);
  return buf;
}

}  // namespace

// Darker point colours give unstable ratios (a small shift of the sampled pixel, a blend with
// a neighbour, JPEG noise are large relative to the value): they are left out.
constexpr float kDarkest = 0.15f;

namespace {

// A track element of a training view: the pixel (y · width + x, full resolution) where SfM
// point `point` projects, inside the frame and on a kept pixel.
struct TrackSample {
  long long pixel;
  size_t point;
};

std::vector<std::vector<TrackSample>> track_samples(const TrainingData& data) {
  const size_t n = data.points.size();
  if (data.point_train_views.size() != n || data.colors.size() != n)
    throw std::invalid_argument("examine_effects: track information does not match the points");
  std::vector<std::vector<TrackSample>> samples(data.train.size());
  for (size_t i = 0; i < n; ++i)
    for (const int32_t v : data.point_train_views[i]) {
      if (v < 0 || size_t(v) >= data.train.size())
        throw std::invalid_argument("examine_effects: a track names a training view that does not exist");
      const TrainView& view = data.train[size_t(v)];
      const long long pixel = view.camera.pixel_of(data.points[i]);
      if (pixel < 0 || (!view.keep.empty() && view.keep[size_t(pixel)] == 0)) continue;
      samples[size_t(v)].push_back({pixel, i});
    }
  return samples;
}

}  // namespace

EffectsEvidence examine_effects(const TrainingData& data, const EffectsRules& r, Communicator* comm) {
  EffectsEvidence ev;
  const int rank = comm ? comm->rank() : 0, ranks = comm ? comm->size() : 1;
  // Per view, on the rank that holds its photo: per channel, log₂(photo / point colour) of
  // every sample whose colours are neither near black nor near saturation (where a ratio says
  // nothing about exposure), and the open sky above the scene.
  const std::vector<std::vector<TrackSample>> track = track_samples(data);
  constexpr size_t kFields = 5;  // log2_gain[3], open_top_share, gain_judged
  std::vector<double> judged_values(kFields * data.train.size(), 0.0);
  for (size_t v = 0; v < data.train.size(); ++v) {
    if (rank_of_view(v, ranks) != rank) continue;
    std::array<std::vector<double>, 3> ratios;
    for (const TrackSample& s : track[v])
      for (int c = 0; c < 3; ++c) {
        const float point = data.colors[s.point][c] / 255.0f,
                    photo = byte_to_float(data.train[v].image.pixels[3 * size_t(s.pixel) + c]);
        if (point > kDarkest && point < 0.95f && photo > 0.02f && photo < 0.98f)
          ratios[c].push_back(std::log2(double(photo) / point));
      }
    double* out = &judged_values[kFields * v];
    if (track[v].size() >= size_t(r.min_samples_per_view)) {
      const TrainView& view = data.train[v];
      std::vector<long long> pixels;
      for (const TrackSample& s : track[v]) pixels.push_back(s.pixel);
      const OpenSkyCells sky = open_sky_cells(view.camera, view.image, pixels, r.sky_grid, r.sky_smooth_ratio);
      out[3] = float(sky.share(view.camera.width, view.camera.height));
    }
    bool judged = true;
    for (int c = 0; c < 3; ++c) {
      judged &= ratios[c].size() >= size_t(r.min_samples_per_view);
      out[c] = float(median(ratios[c]));
    }
    out[4] = judged;
  }
  // Every rank receives every view's values (each from its own rank; zeros elsewhere).
  if (comm) comm->sum(std::span(judged_values));
  std::vector<double> brightness, open_shares;
  std::array<std::vector<double>, 3> balance;  // per channel, over views
  for (size_t v = 0; v < data.train.size(); ++v) {
    const double* in = &judged_values[kFields * v];
    ViewEvidence e{data.train[v].name, int(track[v].size()), {float(in[0]), float(in[1]), float(in[2])}, 0.0f};
    if (track[v].size() >= size_t(r.min_samples_per_view)) {
      e.open_top_share = float(in[3]);
      open_shares.push_back(e.open_top_share);
    }
    e.gain_judged = in[4] != 0;
    if (e.gain_judged) {
      const double mean_gain = (e.log2_gain[0] + e.log2_gain[1] + e.log2_gain[2]) / 3.0;
      brightness.push_back(mean_gain);
      for (int c = 0; c < 3; ++c) balance[c].push_back(e.log2_gain[c] - mean_gain);
      ++ev.judged_views;
    }
    ev.views.push_back(e);
  }
  if (open_shares.size() < 3) {
    ev.background_reason = "only " + std::to_string(open_shares.size()) + " training views have " +
                           std::to_string(r.min_samples_per_view) + " or more SfM track samples, too few to judge";
  } else {
    ev.open_top_share = median(open_shares);
    ev.background = ev.open_top_share > r.sky_share;
    ev.background_reason =
        "in the median training view, " + fixed2(100 * ev.open_top_share) +
        " % of the frame is open sky above the scene (smooth, no SfM point, connected to the top edge; " +
        "threshold " + fixed2(100 * r.sky_share) + " %)";
  }
  if (ev.judged_views < 3) {
    ev.reason = "only " + std::to_string(ev.judged_views) + " training views have " +
                std::to_string(r.min_samples_per_view) + " or more usable SfM track samples, too few to judge";
    return ev;
  }
  ev.exposure_spread_stops = robust_spread(brightness);
  // Per channel across views: a cast every photo shares (or a bias of the point colours) is
  // not a difference between the photos.
  for (int c = 0; c < 3; ++c) ev.white_balance_spread = std::max(ev.white_balance_spread, robust_spread(balance[c]));
  ev.appearance =
      ev.exposure_spread_stops > r.exposure_spread_stops || ev.white_balance_spread > r.white_balance_spread;
  ev.reason = "over " + std::to_string(ev.judged_views) + " training views the brightness spreads by " +
              fixed2(ev.exposure_spread_stops) + " stops (threshold " + fixed2(r.exposure_spread_stops) +
              ") and the colour balance by " + fixed2(ev.white_balance_spread) + " (threshold " +
              fixed2(r.white_balance_spread) + ")";
  return ev;
}

std::vector<std::array<float, 3>> view_gains(const TrainingData& data, const EffectsRules& rules, Communicator* comm) {
  const EffectsEvidence ev = examine_effects(data, rules, comm);
  std::vector<std::array<float, 3>> gains(data.train.size(), {1.0f, 1.0f, 1.0f});
  for (size_t v = 0; v < ev.views.size(); ++v)
    if (ev.views[v].gain_judged)
      for (int c = 0; c < 3; ++c) gains[v][c] = std::exp2(ev.views[v].log2_gain[c]);
  return gains;
}

Effects choose_effects(const Effects& configured, const EffectsEvidence& evidence, std::vector<std::string>& why) {
  Effects chosen = configured;
  chosen.appearance = configured.appearance || evidence.appearance;
  why.push_back(std::string("appearance ") + (chosen.appearance ? "on" : "off") + ": " + evidence.reason +
                (configured.appearance && !evidence.appearance ? "; on because --config turns it on" : ""));
  chosen.background = configured.background || evidence.background;
  why.push_back(std::string("background ") + (chosen.background ? "on" : "off") + ": " + evidence.background_reason +
                (configured.background && !evidence.background ? "; on because --config turns it on" : ""));
  return chosen;
}

}  // namespace desplat
