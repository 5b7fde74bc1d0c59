#include "desplat/jobs/training_eta.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
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

double GrowthForecast::relative_count(int64_t done, int64_t v) const {
  if (cycle <= 0) return 1;
  const double reference = rate_count > 0 ? rate_count : count_now;
  if (v <= grows_from) return count_now / reference;
  // The share of cycle k before grows_until, in [0, 1]; none for a cycle over before grows_from.
  auto part = [&](int64_t k) {
    if ((k + 1) * cycle <= grows_from) return 0.0;
    return std::clamp(double(grows_until - k * cycle) / double(cycle), 0.0, 1.0);
  };
  const int64_t now = done / cycle;
  const double start = start_count > 0 ? start_count : count_now;
  double count = count_now;
  if (done < grows_until && part(now) > 0) count = std::max(count_now, start * std::pow(factor, part(now)));
  for (int64_t k = now + 1; k <= v / cycle; ++k) count *= std::pow(factor, part(k));
  return count / reference;
}

int64_t GrowthForecast::next_change(int64_t v) const {
  if (cycle <= 0) return std::numeric_limits<int64_t>::max();
  if (v <= grows_from) return std::min(grows_from + 1, (v / cycle + 1) * cycle);
  return (v / cycle + 1) * cycle;
}

double predict_remaining_seconds(const TrainConfig& schedule, int64_t done, int64_t total, double rate,
                                 const std::map<Phase, double>& render_seconds, const GrowthForecast& growth) {
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
    const int64_t end = std::min(phase_end(schedule, v, total), growth.next_change(v));
    seconds += double(end - v) * std::max(0.0, rate + render(phase_at(schedule, v)) - current) *
               growth.relative_count(done, v);
    v = end;
  }
  return seconds;
}

std::string format_eta(double seconds) {
  if (seconds < 0) return "--";
  return format_duration(seconds, DurationStyle::compact);
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
    window_count_sum_ = 0;
    phase_ = phase;
  }
  observe_growth(done, gaussians);
  if (!window_.empty()) window_count_sum_ += double(gaussians);
  window_.push_back({done, now, double(gaussians)});
  while (window_.size() > 2 && window_.back().done - window_[1].done >= kMaxWindow) {
    window_count_sum_ -= window_[1].count;  // it becomes the oldest, which the mean leaves out
    window_.pop_front();
  }
  const Sample& oldest = window_.front();
  if (window_.back().done - oldest.done >= kMinWindow) {
    rate_ = (window_.back().seconds - oldest.seconds) / double(window_.back().done - oldest.done);
    // The count the rate stands for: the mean over the steps it was measured on.
    growth_.rate_count = window_count_sum_ / double(window_.size() - 1);
  }
  for (Estimate& e : estimates_)
    if (e.done < 0 && rate_ >= 0 && done - first_ >= (total_ - first_) * e.percent / 100) {
      e.done = done;
      e.at_seconds = elapsed;
      e.predicted = remaining(done);
      e.growth_factor = growth_.cycle > 0 ? growth_.factor : 1.0;
    }
}

void TrainingEta::observe_growth(int64_t done, size_t gaussians) {
  const DensifySettings& d = config_.densify;
  const int64_t cycle = int64_t(d.reset_alpha_every) * d.refine_every;
  if (!d.enabled || cycle <= 0) {
    growth_.cycle = 0;
    return;
  }
  const int64_t c = done / cycle;
  if (c != cycle_) {
    // The cycle just left, if it followed an opacity reset (not the job's first: that one grows
    // from the SfM points, by how far they fall short of the photos' detail), this run saw it
    // from its start and densification ran through it.
    if (cycle_ >= 1 && c == cycle_ + 1 && cycle_start_seen_ && c * cycle <= d.stop_split_at &&
        growth_.start_count > 0 && gaussians > 0)
      growth_.factor = double(gaussians) / growth_.start_count;
    // No refinement but the one at the cycle's first view has run since it began, so the count
    // is the one the cycle started from.
    cycle_start_seen_ = done - c * cycle < d.refine_every;
    growth_.start_count = cycle_start_seen_ ? double(gaussians) : 0;
    cycle_ = c;
  }
  growth_.cycle = cycle;
  growth_.grows_from = d.warmup;
  growth_.grows_until = d.stop_split_at;
  growth_.count_now = double(std::max<size_t>(1, gaussians));
}

double TrainingEta::remaining(int64_t done) const {
  if (rate_ < 0) return -1;
  return predict_remaining_seconds(config_, done, total_, rate_, render_seconds_, growth_);
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
                   {"growth_factor", e.growth_factor},
                   {"error", actual > 0 ? nlohmann::json(e.predicted / actual - 1) : nlohmann::json(nullptr)}});
  }
  return out;
}

}  // namespace desplat
