#include "desplat/jobs/training_eta.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "desplat/core/stopwatch.hpp"
#include "jobs/text_format.hpp"

namespace desplat {

Phase phase_at(const TrainConfig& schedule, int64_t view) {
  return {schedule.downscale_at(view), schedule.sh_degree_at(view)};
}

int64_t phase_end(const TrainConfig& schedule, int64_t view, int64_t total) {
  int64_t end = total;
  // The factor halves at multiples of resolution_schedule until it is 1; the degree rises at
  // multiples of sh_degree_interval until it is sh_degree.
  if (schedule.downscale_at(view) > 1 && schedule.resolution_schedule > 0)
    end = std::min(end, (view / schedule.resolution_schedule + 1) * schedule.resolution_schedule);
  if (schedule.sh_degree_at(view) < schedule.sh_degree && schedule.sh_degree_interval > 0)
    end = std::min(end, (view / schedule.sh_degree_interval + 1) * schedule.sh_degree_interval);
  return std::max(end, view + 1);
}

double predict_remaining_seconds(const TrainConfig& schedule, int64_t done, int64_t total, double rate,
                                 const std::map<Phase, double>& render_seconds) {
  if (done >= total) return 0;
  auto render = [&](Phase p) {
    const auto it = render_seconds.find(p);
    if (it == render_seconds.end())
      throw std::logic_error("predict_remaining_seconds: no render time for factor " + std::to_string(p.factor) +
                             ", SH degree " + std::to_string(p.sh_degree));
    return it->second;
  };
  const double current = render(phase_at(schedule, done));
  double seconds = 0;
  for (int64_t v = done; v < total;) {
    const int64_t end = phase_end(schedule, v, total);
    seconds += double(end - v) * std::max(0.0, rate + render(phase_at(schedule, v)) - current);
    v = end;
  }
  return seconds;
}

std::string format_eta(double seconds, bool growing) {
  if (seconds < 0) return "--";
  return format_duration(seconds, DurationStyle::compact) + (growing ? "+" : "");
}

RenderTimer wall_clock_render_timer() {
  struct Scratch {
    RasterOutput forward;
    RasterGradients grads;
    std::vector<float> d_color, d_alpha;
  };
  auto scratch = std::make_shared<Scratch>();
  return [scratch](const GaussianView& g, const Camera& camera, const RasterSettings& rs) {
    const Stopwatch watch;
    const size_t pixels = size_t(camera.width) * camera.height;
    scratch->d_color.assign(3 * pixels, 1e-3f);
    scratch->d_alpha.assign(pixels, 1e-3f);
    rasterize_forward(g, camera, rs, scratch->forward);
    rasterize_backward(g, camera, rs, scratch->forward, scratch->d_color, scratch->d_alpha, {}, scratch->grads);
    return watch.seconds();
  };
}

TrainingEta::TrainingEta(const TrainConfig& config, int64_t first, int64_t total, RenderTimer timer)
    : config_(config), first_(first), total_(total), timer_(std::move(timer)) {}

void TrainingEta::time_renders(const Trainer& trainer, int64_t from) {
  const TrainingData& data = trainer.data();
  // A view this rank holds (each rank times its own; only rank 0 prints).
  size_t view = 0;
  while (view + 1 < data.train.size() && !trainer.owns_view(view)) ++view;
  const GaussianView g = trainer.gaussians().params.view();
  // Every phase the views from `from` on reach.
  for (int64_t v = from; v < total_; v = phase_end(config_, v, total_)) {
    const Phase phase = phase_at(config_, v);
    const Camera camera = downscale_camera(data.train.at(view).camera, phase.factor);
    RasterSettings rs;
    rs.num_threads = config_.threads;
    rs.isa = config_.kernel_isa;
    rs.active_sh_degree = phase.sh_degree;
    // The fastest of kTimings renders: what the render costs without the machine's other load
    // (the timings of a shared machine scatter upwards). The first timing of a phase also
    // sizes the timer's buffers, and is not counted.
    const bool first = !render_seconds_.count(phase);
    double fastest = INFINITY;
    for (int k = 0; k < kTimings + (first ? 1 : 0); ++k) {
      const double seconds = timer_(g, camera, rs);
      timing_seconds_ += seconds;
      if (!(first && k == 0)) fastest = std::min(fastest, seconds);
    }
    render_seconds_[phase] = fastest;
  }
  timed_gaussians_ = trainer.gaussians().size();
  timed_at_ = from;
}

void TrainingEta::observe(const Trainer& trainer, int64_t done, double elapsed) {
  if (done >= total_) return;
  const double now = clock(elapsed);  // before any timing below: `elapsed` holds none of it
  const Phase phase = phase_at(config_, done);
  const size_t gaussians = trainer.gaussians().size();
  const bool new_phase = !(phase == phase_);
  // A fifth more or fewer Gaussians than at the last timing, 100 views on at the earliest.
  const bool moved = timed_at_ >= 0 && done - timed_at_ >= 100 &&
                     std::abs(double(gaussians) - double(timed_gaussians_)) > 0.2 * double(timed_gaussians_);
  // On a new phase the one just left is timed again too, so the shift below compares two
  // renders of the same Gaussians.
  if (new_phase || moved || timed_at_ < 0) time_renders(trainer, new_phase && done > first_ ? done - 1 : done);
  if (new_phase) {
    // The new phase's rate, until it has its own: the last one, shifted by the renders.
    if (rate_ >= 0 && render_seconds_.count(phase_))
      rate_ = std::max(0.0, rate_ + render_seconds_[phase] - render_seconds_[phase_]);
    window_.clear();
    phase_ = phase;
  }
  window_.push_back({done, now});
  while (window_.size() > 2 && window_.back().done - window_[1].done >= kMaxWindow) window_.erase(window_.begin());
  const Sample& oldest = window_.front();
  if (window_.back().done - oldest.done >= kMinWindow)
    rate_ = (window_.back().seconds - oldest.seconds) / double(window_.back().done - oldest.done);
  for (Estimate& e : estimates_)
    if (e.done < 0 && rate_ >= 0 && done - first_ >= (total_ - first_) * e.percent / 100) {
      e.done = done;
      e.at_seconds = elapsed;
      e.predicted = remaining(done);
    }
}

double TrainingEta::remaining(int64_t done) const {
  if (rate_ < 0) return -1;
  return predict_remaining_seconds(config_, done, total_, rate_, render_seconds_);
}

nlohmann::json TrainingEta::accuracy(double total_elapsed) const {
  nlohmann::json out = nlohmann::json::array();
  for (const Estimate& e : estimates_) {
    if (e.done < 0) continue;
    const double actual = total_elapsed - e.at_seconds;
    out.push_back({{"percent", e.percent},
                   {"views_done", e.done},
                   {"predicted_seconds", e.predicted},
                   {"actual_seconds", actual},
                   {"error", actual > 0 ? nlohmann::json(e.predicted / actual - 1) : nlohmann::json(nullptr)}});
  }
  return out;
}

}  // namespace desplat
