// The training time left, as the progress line shows it (how close it comes: docs/BENCHMARKS.md,
// "The ETA").
//
// The model: a training view's time is a part that does not depend on the schedule (density
// control, bookkeeping) plus the static layer's render, forward and backward, which depends
// on the resolution and the SH degree the schedule sets (Phase). The rate measured over the
// last views of the current phase stands for the rest of it; a coming phase costs that rate
// plus the difference of one timed forward + backward render of a training view in the two
// phases, with the current Gaussians. The renders are timed again when the phase changes or
// the Gaussian count has moved by a fifth.
//
// Every view's cost is then scaled by the static Gaussians' count foreseen for it over the
// count the rate was measured at (GrowthForecast): a step's work (projection, binning, pixel pairs, Adam) grows
// with the count, which densification can still multiply several times after the first tenth
// of a run. Not modelled: Adam's share of the higher SH bands, the distractor Gaussians
// (BENCHMARKS.md, "The ETA", how far off the whole leaves it).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/train/train_config.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

// A stretch of the schedule with one resolution factor (TrainConfig::downscale_at) and one SH
// degree (sh_degree_at): the views of a phase cost alike, up to the Gaussians' growth.
struct Phase {
  int factor = 0, sh_degree = -1;
  bool operator==(const Phase&) const = default;
  auto operator<=>(const Phase&) const = default;
};
Phase phase_at(const TrainConfig& schedule, int64_t view);
// The first view after `view` (< total) in another phase, or `total`.
int64_t phase_end(const TrainConfig& schedule, int64_t view, int64_t total);

// The static Gaussians' count over the views to come, relative to the count the rate was
// measured at (a step's work grows with the count).
// Densification works in cycles of `cycle` views (reset_alpha_every·refine_every; each after
// the first opens with an opacity reset, after which the Gaussians whose gradients rise
// split): the count climbs early in a cycle and then holds (BENCHMARKS.md, "The ETA"). So the
// forecast is a step per cycle: the current cycle ends at max(now, start_count × factor), each
// later cycle multiplies that by `factor`, and a cycle only part of which lies before
// `grows_until` (densify.stop_split_at) by factor^(that part). Views up to `grows_from`
// (densify.warmup), before the first refinement, keep the count, and cycles over by then do
// not grow.
struct GrowthForecast {
  int64_t cycle = 0;        // views per cycle; 0: the count stays as it is
  int64_t grows_from = 0;   // the last view before densification can add
  int64_t grows_until = 0;  // the first view at which densification no longer adds
  double factor = 1;        // growth over one cycle, > 0
  double start_count = 0;   // the count when the current cycle began (≤ 0: unknown, taken as now)
  double count_now = 1;     // > 0
  double rate_count = 0;    // the count the rate was measured at (≤ 0: count_now)
  // The count foreseen at view v (≥ the current view `done`) over rate_count: what a view
  // at the rate then costs, relative to the rate (1 for every view when cycle is 0). Pure.
  double relative_count(int64_t done, int64_t v) const;
  // The first view after v (≥ done) at which relative_count changes, or a view ≥ total.
  int64_t next_change(int64_t v) const;
};

// Seconds for the training views [done, total) when view v of phase p costs
// (rate + render_seconds[p] − render_seconds[phase_at(done)]) × growth.relative_count(done, v)
// (render_seconds holds every phase the views reach). Pure.
double predict_remaining_seconds(const TrainConfig& schedule, int64_t done, int64_t total, double rate,
                                 const std::map<Phase, double>& render_seconds, const GrowthForecast& growth = {});

// Seconds one static render takes, forward and backward, of `g` seen by `camera`: the time
// it takes to answer, which TrainingEta leaves out of its rates.
using RenderTimer = std::function<double(const GaussianView& g, const Camera& camera, const RasterSettings& rs)>;
// The real one: rasterize_forward + rasterize_backward, timed by the wall clock (its buffers
// are its own and kept between calls).
RenderTimer wall_clock_render_timer();

// The progress line's ETA: "--" while unknown (seconds < 0), else the compact duration.
std::string format_eta(double seconds);

class TrainingEta {
 public:
  // A run of views [first, total) of `config`'s schedule.
  TrainingEta(const TrainConfig& config, int64_t first, int64_t total, RenderTimer timer = wall_clock_render_timer());

  // After each step: `done` views of the job trained, `elapsed` seconds of this run so far
  // (its clock, which includes the time the renders here were timed: that is left out of
  // the rates). May time the static renders (see above), on this thread's trainer.
  void observe(const Trainer& trainer, int64_t done, double elapsed);

  // Seconds left after `done` views; negative until a rate is known (the first
  // kMinWindow views of the run).
  double remaining(int64_t done) const;

  // The estimates made when the run passed 10, 25 and 50 % of its views, each with the time
  // it took from there (`total_elapsed`: the run's training seconds), for metrics.json.
  nlohmann::json accuracy(double total_elapsed) const;
  // Seconds spent timing renders so far (part of the run's training time).
  double timing_seconds() const { return timing_seconds_; }

  static constexpr int64_t kMinWindow = 20;   // views a rate is measured over, at least
  static constexpr int64_t kMaxWindow = 400;  // … and at most (the recent rate, as Gaussians grow)
  static constexpr int kTimings = 3;          // renders per phase each time, the fastest kept
  // A cycle's growth until the run has completed one after an opacity reset (the job's first
  // cycle is not one: it grows from the SfM points, by how far they fall short of the photos'
  // detail, which no evidence at its start tells). The reset cycles of the scenes in
  // BENCHMARKS.md, "The ETA", grew 1.40–1.58×.
  static constexpr double kCycleGrowth = 1.5;
  // The forecast the estimate uses now.
  const GrowthForecast& growth() const { return growth_; }

 private:
  // Times a render at every factor the views [from, total) reach.
  void time_renders(const Trainer& trainer, int64_t from);
  double clock(double elapsed) const { return elapsed - timing_seconds_; }
  // Follows the densification cycles: the count each began with, the last complete one's growth.
  void observe_growth(int64_t done, size_t gaussians);

  TrainConfig config_;
  int64_t first_, total_;
  struct Sample {
    int64_t done;
    double seconds;  // the run's clock without the render timing
    double count;    // static Gaussians after the step
  };
  std::deque<Sample> window_;    // this phase's recent samples, oldest first
  double window_count_sum_ = 0;  // Σ count over window_ but its oldest (integers: exact)
  Phase phase_;                  // of the last view observed (none at first)
  double rate_ = -1;             // seconds per view in that phase; < 0 before one is known
  std::map<Phase, double> render_seconds_;
  size_t timed_gaussians_ = 0;
  int64_t timed_at_ = -1;
  double timing_seconds_ = 0;
  struct Estimate {
    int percent;
    int64_t done = -1;
    double at_seconds = 0, predicted = 0;
    double growth_factor = 1;  // the forecast's factor per cycle then
  };
  std::vector<Estimate> estimates_{{10}, {25}, {50}};
  GrowthForecast growth_{.factor = kCycleGrowth};
  int64_t cycle_ = -1;             // the densification cycle of the last view observed
  bool cycle_start_seen_ = false;  // whether this run observed that cycle from its first view
  RenderTimer timer_;
};

}  // namespace desplat
