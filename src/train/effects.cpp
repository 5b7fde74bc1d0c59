#include "desplat/train/effects.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "desplat/core/statistics.hpp"

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
      throw std::invalid_argument("--effects: 'background' is not available yet (none, auto, or a list of "
                                  "distractors, appearance)");
    } else {
      throw std::invalid_argument("--effects: unknown effect '" + name +
                                  "' (none, or a comma-separated list of distractors, appearance)");
    }
    any = true;
  }
  if (!any) throw std::invalid_argument("--effects is empty (none, or a comma-separated list of distractors, appearance)");
  return e;
}

Effects Effects::of(const TrainConfig& config) { return {config.distractors.enabled, config.appearance.enabled}; }

void Effects::apply(TrainConfig& config) const {
  config.distractors.enabled = distractors;
  config.appearance.enabled = appearance;
}

std::string Effects::to_string() const {
  std::string out;
  for (auto [on, name] : {std::pair{distractors, "distractors"}, std::pair{appearance, "appearance"}})
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

EffectsEvidence examine_effects(const TrainingData& data, const EffectsRules& r) {
  EffectsEvidence ev;
  const size_t n = data.points.size();
  if (data.point_train_views.size() != n || data.colors.size() != n)
    throw std::invalid_argument("examine_effects: track information does not match the points");
  // Per view and channel, log₂(photo / point colour) of every sample whose colours are neither
  // near black nor near saturation (where a ratio says nothing about exposure).
  std::vector<std::array<std::vector<double>, 3>> ratios(data.train.size());
  std::vector<int> samples(data.train.size(), 0);
  for (size_t i = 0; i < n; ++i)
    for (const int32_t v : data.point_train_views[i]) {
      if (v < 0 || size_t(v) >= data.train.size())
        throw std::invalid_argument("examine_effects: a track names a training view that does not exist");
      const TrainView& view = data.train[size_t(v)];
      const long long pixel = view.camera.pixel_of(data.points[i]);
      if (pixel < 0 || (!view.keep.empty() && view.keep[size_t(pixel)] == 0)) continue;
      ++samples[size_t(v)];
      for (int c = 0; c < 3; ++c) {
        const float point = data.colors[i][c] / 255.0f, photo = view.image.pixels[3 * size_t(pixel) + c];
        if (point > kDarkest && point < 0.95f && photo > 0.02f && photo < 0.98f)
          ratios[size_t(v)][c].push_back(std::log2(double(photo) / point));
      }
    }
  std::vector<double> brightness;
  std::array<std::vector<double>, 3> balance;  // per channel, over views
  for (size_t v = 0; v < data.train.size(); ++v) {
    ViewEvidence e{data.train[v].name, samples[v], {0, 0, 0}};
    bool judged = true;
    for (int c = 0; c < 3; ++c) {
      judged &= ratios[v][c].size() >= size_t(r.min_samples_per_view);
      e.log2_gain[c] = float(median(ratios[v][c]));
    }
    if (judged) {
      const double mean_gain = (e.log2_gain[0] + e.log2_gain[1] + e.log2_gain[2]) / 3.0;
      brightness.push_back(mean_gain);
      for (int c = 0; c < 3; ++c) balance[c].push_back(e.log2_gain[c] - mean_gain);
      ++ev.judged_views;
    }
    ev.views.push_back(e);
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

Effects choose_effects(const Effects& configured, const EffectsEvidence& evidence, std::vector<std::string>& why) {
  Effects chosen = configured;
  chosen.appearance = configured.appearance || evidence.appearance;
  why.push_back(std::string("distractors ") + (chosen.distractors ? "on" : "off") +
                ": as the preset and --config set them (no test for transients before training is reliable yet)");
  why.push_back(std::string("appearance ") + (chosen.appearance ? "on" : "off") + ": " + evidence.reason +
                (configured.appearance && !evidence.appearance ? "; on because --config turns it on" : ""));
  return chosen;
}

}  // namespace desplat
