#include "desplat/train/transient_probe.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "desplat/core/statistics.hpp"
#include "desplat/raster/raster.hpp"

namespace desplat {
namespace {

std::array<double, 3> axis_of(const Camera& c) { return {c.R_cw[6], c.R_cw[7], c.R_cw[8]}; }

// Per view, up to rules.neighbours other views: nearest camera centres first, among those
// whose optical axis lies within rules.max_axis_angle_deg (they photograph the same side).
std::vector<std::vector<int>> neighbours_of(const std::vector<ProbeView>& views, const TransientRules& rules) {
  const double min_cos = std::cos(double(rules.max_axis_angle_deg) * M_PI / 180.0);
  std::vector<std::vector<int>> out(views.size());
  for (size_t v = 0; v < views.size(); ++v) {
    const auto cv = views[v].camera.center();
    const auto av = axis_of(views[v].camera);
    std::vector<std::pair<double, int>> near;
    for (size_t u = 0; u < views.size(); ++u) {
      if (u == v) continue;
      const auto au = axis_of(views[u].camera);
      if (av[0] * au[0] + av[1] * au[1] + av[2] * au[2] < min_cos) continue;
      const auto cu = views[u].camera.center();
      const double d2 =
          std::pow(double(cu[0]) - cv[0], 2) + std::pow(double(cu[1]) - cv[1], 2) + std::pow(double(cu[2]) - cv[2], 2);
      near.emplace_back(d2, int(u));
    }
    std::sort(near.begin(), near.end());
    for (size_t k = 0; k < near.size() && int(k) < rules.neighbours; ++k) out[v].push_back(near[k].second);
  }
  return out;
}

// Sizes of the 4-connected areas of `mask` [h·w] (1 = set).
std::vector<int> area_sizes(const std::vector<uint8_t>& mask, int w, int h) {
  std::vector<uint8_t> seen(mask.size(), 0);
  std::vector<int> sizes, stack;
  for (int start = 0; start < w * h; ++start) {
    if (!mask[start] || seen[start]) continue;
    int n = 0;
    stack.assign(1, start);
    seen[start] = 1;
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      ++n;
      const int x = p % w, y = p / w;
      const int next[4][2] = {{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}};
      for (const auto& q : next) {
        if (q[0] < 0 || q[0] >= w || q[1] < 0 || q[1] >= h) continue;
        const int i = q[1] * w + q[0];
        if (mask[i] && !seen[i]) seen[i] = 1, stack.push_back(i);
      }
    }
    sizes.push_back(n);
  }
  return sizes;
}

}  // namespace

TransientEvidence judge_transients(const std::vector<ProbeView>& views, const TransientRules& rules) {
  for (const ProbeView& v : views) {
    const size_t pixels = size_t(v.camera.width) * size_t(v.camera.height);
    if (v.error.size() != pixels || v.depth.size() != pixels)
      throw std::invalid_argument("judge_transients: a probe view's error or depth map does not match its camera");
  }
  const std::vector<std::vector<int>> near = neighbours_of(views, rules);
  TransientEvidence ev;
  ev.view_share.assign(views.size(), 0.0f);
  std::vector<double> seen;
  for (size_t v = 0; v < views.size(); ++v) {
    if (near[v].size() < 2) continue;
    ++ev.judged_views;
    const ProbeView& pv = views[v];
    const Camera& cam = pv.camera;
    const int w = cam.width, h = cam.height;
    std::vector<uint8_t> specific(size_t(w) * h, 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t p = size_t(y) * w + x;
        if (pv.error[p] < rules.tolerance || pv.depth[p] <= 0) continue;
        const double z = pv.depth[p];
        const auto X = cam.to_world({(x + 0.5 - cam.cx) / cam.fx * z, (y + 0.5 - cam.cy) / cam.fy * z, z});
        seen.clear();
        for (const int u : near[v]) {
          const ProbeView& nu = views[size_t(u)];
          const long long q = nu.camera.pixel_of(X);
          if (q < 0 || nu.depth[size_t(q)] <= 0 || nu.error[size_t(q)] < 0) continue;
          const Camera& c = nu.camera;
          const double zu = double(c.R_cw[6]) * X[0] + double(c.R_cw[7]) * X[1] + double(c.R_cw[8]) * X[2] + c.t_cw[2];
          // Judged only where u sees the same surface: nearer (hidden behind something in u)
          // or farther (u sees through where the probe put a surface in v) says nothing.
          if (std::fabs(zu - nu.depth[size_t(q)]) > rules.depth_tolerance * nu.depth[size_t(q)]) continue;
          seen.push_back(nu.error[size_t(q)]);
        }
        if (seen.size() >= 2 && median(seen) <= double(rules.neighbour_fraction) * rules.tolerance) specific[p] = 1;
      }
    int counted = 0;
    for (const int n : area_sizes(specific, w, h))
      if (n >= rules.min_area * float(w) * float(h)) counted += n;
    ev.view_share[v] = float(counted) / float(w * h);
    if (ev.view_share[v] >= rules.view_share) ++ev.views_with_transients;
  }
  const int needed = std::max(2, int(std::ceil(rules.min_views_share * float(ev.judged_views))));
  ev.transients = ev.views_with_transients >= needed;
  char line[320];
  std::snprintf(line, sizeof line,
                "%d of %d judged views hold an area of at least %.1f %% of the frame that a static probe leaves "
                "unexplained while neighbouring views explain it (%d needed for distractors)",
                ev.views_with_transients, ev.judged_views, 100.0 * rules.view_share, needed);
  ev.reason = line;
  return ev;
}

int probe_factor(int width, int height, const TransientRules& rules) {
  const int side = std::min(width, height);
  int factor = 1;
  while (2 * factor <= rules.max_probe_factor && side / (2 * factor) >= rules.min_probe_side) factor *= 2;
  return factor;
}

ProbeView probe_view(const Trainer& probe, size_t v, int factor) {
  const TrainView& tv = probe.data().train.at(v);
  ProbeView pv;
  pv.camera = downscale_camera(tv.camera, factor);
  const int w = pv.camera.width, h = pv.camera.height;
  // The view's own look as it was trained: with a shared embedding the sky reads the appearance
  // embedding, not the background's own (unused) one.
  const FloatImage render = probe.render(pv.camera, probe.config().eval_background, probe.training_look(v));
  const ByteImage photo = downscale_bytes(tv.image, factor);
  const std::vector<uint8_t> keep =
      tv.keep.empty() ? std::vector<uint8_t>{} : downscale_keep(tv.keep, tv.camera.width, tv.camera.height, factor);
  pv.error.assign(size_t(w) * h, 0.0f);
  for (size_t p = 0; p < pv.error.size(); ++p) {
    if (!keep.empty() && !keep[p]) {
      pv.error[p] = -1;
      continue;
    }
    float sum = 0;
    for (int c = 0; c < 3; ++c) sum += std::fabs(render.pixels[3 * p + c] - byte_to_float(photo.pixels[3 * p + c]));
    pv.error[p] = sum / 3;
  }
  RasterOutput fw;
  rasterize_forward(probe.gaussians().params.view(), pv.camera, probe.raster_settings(), fw);
  pv.depth.assign(size_t(w) * h, 0.0f);
  for (size_t p = 0; p < pv.depth.size(); ++p)
    if (fw.alpha[p] >= 0.5f) pv.depth[p] = fw.depth[p] / fw.alpha[p];
  return pv;
}

std::optional<TransientEvidence> probe_transients(const TrainingData& data, TrainConfig config,
                                                  const TransientRules& rules, const std::atomic<bool>* stop,
                                                  Communicator* comm) {
  if (rules.probe_steps < 1) throw std::invalid_argument("probe_transients: probe_steps must be at least 1");
  if (data.train.empty()) return judge_transients({}, rules);
  // Every probe step at 1/factor: the schedule's factor is 2^num_downscales.
  const Camera& first = data.train.front().camera;
  int downscales = 0;
  while ((2 << downscales) <= probe_factor(first.width, first.height, rules)) ++downscales;
  config.distractors.enabled = false;
  config.iterations = rules.probe_steps;
  config.num_downscales = downscales;
  config.resolution_schedule = rules.probe_steps + 1;
  Trainer probe(data, config, comm);
  for (int s = 0; s < rules.probe_steps; ++s) {
    if (any_rank(comm, stop && stop->load())) return std::nullopt;
    probe.step();
  }

  // Each view's maps on the rank holding its photo; every rank judges all of them.
  const int factor = 1 << downscales;
  std::vector<ProbeView> views(data.train.size());
  for (size_t v = 0; v < data.train.size(); ++v) {
    if (probe.owns_view(v)) views[v] = probe_view(probe, v, factor);
    if (!comm || comm->size() == 1) continue;
    const int holder = rank_of_view(v, comm->size());
    views[v].camera = downscale_camera(data.train[v].camera, factor);
    broadcast_vector(*comm, views[v].error, holder);
    broadcast_vector(*comm, views[v].depth, holder);
  }
  return judge_transients(views, rules);
}

}  // namespace desplat
