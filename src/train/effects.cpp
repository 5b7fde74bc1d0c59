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
      e.background = true;
    } else {
      throw std::invalid_argument("--effects: unknown effect '" + name +
                                  "' (none, or a comma-separated list of distractors, appearance, background)");
    }
    any = true;
  }
  if (!any)
    throw std::invalid_argument("--effects is empty (none, or a comma-separated list of distractors, appearance, "
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
  for (auto [on, name] :
       {std::pair{distractors, "distractors"}, std::pair{appearance, "appearance"}, std::pair{background, "background"}})
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

// The share of `view`'s frame in grid cells (`columns` across, square) that look like sky:
// open — none of `samples` (pixel indices) in them — and smooth — their texture (below) under
// smooth_ratio × the median of the cells that hold samples (scale-free: relative to this
// photo's own textured surfaces) — and connected to the top edge through such cells
// (4-neighbours). Open but textured cells are surfaces SfM did not match (a repetitive
// wallpaper), not sky.
float open_top_share(const TrainView& view, const std::vector<long long>& samples, int columns, float smooth_ratio) {
  const Camera& camera = view.camera;
  const int cell = std::max(1, (camera.width + columns - 1) / columns);
  const int cw = (camera.width + cell - 1) / cell, ch = (camera.height + cell - 1) / cell;
  std::vector<uint8_t> occupied(size_t(cw) * ch, 0), open(size_t(cw) * ch, 0);
  for (const long long p : samples)
    occupied[size_t((p / camera.width) / cell) * cw + size_t((p % camera.width) / cell)] = 1;
  // Texture per cell: the mean |Laplacian| of the luminance's kBlock × kBlock means. The means
  // average sensor noise away; the Laplacian ignores a sky's smooth gradient.
  constexpr int kBlock = 4;
  const std::vector<uint8_t>& img = view.image.pixels;
  auto value = [&](size_t i) { return byte_to_float(img[i]); };
  const int bw = camera.width / kBlock, bh = camera.height / kBlock;
  std::vector<float> block(size_t(std::max(bw, 0)) * std::max(bh, 0), 0.0f);
  for (int y = 0; y < bh * kBlock; ++y)
    for (int x = 0; x < bw * kBlock; ++x) {
      const size_t p = 3 * (size_t(y) * camera.width + x);
      block[size_t(y / kBlock) * bw + x / kBlock] +=
          (0.299f * value(p) + 0.587f * value(p + 1) + 0.114f * value(p + 2)) / float(kBlock * kBlock);
    }
  std::vector<double> texture(size_t(cw) * ch, 0.0), count(size_t(cw) * ch, 0.0);
  for (int y = 1; y + 1 < bh; ++y)
    for (int x = 1; x + 1 < bw; ++x) {
      const float* b = &block[size_t(y) * bw + x];
      const float lap = std::abs(b[-1] + b[1] - 2 * b[0]) + std::abs(b[-bw] + b[bw] - 2 * b[0]);
      const size_t c = size_t((y * kBlock + kBlock / 2) / cell) * cw + size_t((x * kBlock + kBlock / 2) / cell);
      texture[c] += lap, count[c] += 1;
    }
  std::vector<double> surface;
  for (size_t c = 0; c < texture.size(); ++c) {
    texture[c] /= std::max(1.0, count[c]);
    if (occupied[c]) surface.push_back(texture[c]);
  }
  const double smooth = smooth_ratio * (surface.empty() ? 0.0 : median(surface));
  auto sky_like = [&](size_t c) { return !occupied[c] && texture[c] <= smooth; };
  std::vector<int> stack;
  for (int x = 0; x < cw; ++x)
    if (sky_like(size_t(x))) open[x] = 1, stack.push_back(x);
  while (!stack.empty()) {
    const int c = stack.back();
    stack.pop_back();
    const int x = c % cw, y = c / cw;
    for (const auto& [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      const int nx = x + dx, ny = y + dy;
      if (nx < 0 || ny < 0 || nx >= cw || ny >= ch) continue;
      const int n = ny * cw + nx;
      if (sky_like(size_t(n)) && !open[n]) open[n] = 1, stack.push_back(n);
    }
  }
  // In pixels, so the partial cells at the right and bottom edges count for what they cover.
  int64_t pixels = 0;
  for (int y = 0; y < ch; ++y)
    for (int x = 0; x < cw; ++x)
      if (open[size_t(y) * cw + x])
        pixels += int64_t(std::min(cell, camera.width - x * cell)) * std::min(cell, camera.height - y * cell);
  return float(double(pixels) / (double(camera.width) * camera.height));
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
  std::vector<std::vector<long long>> sample_pixels(data.train.size());
  for (size_t i = 0; i < n; ++i)
    for (const int32_t v : data.point_train_views[i]) {
      if (v < 0 || size_t(v) >= data.train.size())
        throw std::invalid_argument("examine_effects: a track names a training view that does not exist");
      const TrainView& view = data.train[size_t(v)];
      const long long pixel = view.camera.pixel_of(data.points[i]);
      if (pixel < 0 || (!view.keep.empty() && view.keep[size_t(pixel)] == 0)) continue;
      ++samples[size_t(v)];
      sample_pixels[size_t(v)].push_back(pixel);
      for (int c = 0; c < 3; ++c) {
        const float point = data.colors[i][c] / 255.0f, photo = byte_to_float(view.image.pixels[3 * size_t(pixel) + c]);
        if (point > kDarkest && point < 0.95f && photo > 0.02f && photo < 0.98f)
          ratios[size_t(v)][c].push_back(std::log2(double(photo) / point));
      }
    }
  std::vector<double> brightness, open_shares;
  std::array<std::vector<double>, 3> balance;  // per channel, over views
  for (size_t v = 0; v < data.train.size(); ++v) {
    ViewEvidence e{data.train[v].name, samples[v], {0, 0, 0}, 0.0f};
    if (samples[v] >= r.min_samples_per_view) {
      e.open_top_share = open_top_share(data.train[v], sample_pixels[v], r.sky_grid, r.sky_smooth_ratio);
      open_shares.push_back(e.open_top_share);
    }
    bool judged = true;
    for (int c = 0; c < 3; ++c) {
      judged &= ratios[v][c].size() >= size_t(r.min_samples_per_view);
      e.log2_gain[c] = float(median(ratios[v][c]));
    }
    e.gain_judged = judged;
    if (judged) {
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
    ev.background_reason = "in the median training view, " + fixed2(100 * ev.open_top_share) +
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

std::vector<std::array<float, 3>> view_gains(const TrainingData& data, const EffectsRules& rules) {
  const EffectsEvidence ev = examine_effects(data, rules);
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
