// The progress line's estimate of the time left (desplat/jobs/training_eta.hpp): the model
// against a view-by-view sum, and the estimator on a real trainer with a made-up clock.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "desplat/jobs/training_eta.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

// The model written out view by view: what predict_remaining_seconds sums level by level.
double view_by_view(const TrainConfig& c, int64_t done, int64_t total, double rate, std::map<Phase, double> render) {
  double s = 0;
  for (int64_t v = done; v < total; ++v)
    s += std::max(0.0, rate + render[{c.downscale_at(v), c.sh_degree_at(v)}] -
                           render[{c.downscale_at(done), c.sh_degree_at(done)}]);
  return s;
}

TEST(TrainingEta, PredictionIsTheSumOverTheScheduleViewByView) {
  TrainConfig c;
  c.num_downscales = 2, c.resolution_schedule = 100;
  c.sh_degree = 1, c.sh_degree_interval = 250;
  // 50 views left at 1/4 (1.0 s), 100 at 1/2 (1.0 + 1.5 − 0.5), 50 at full size and degree 0
  // (1.0 + 3.5 − 0.5), 100 at full size and degree 1 (1.0 + 4.5 − 0.5).
  const std::map<Phase, double> render{{{4, 0}, 0.5}, {{2, 0}, 1.5}, {{1, 0}, 3.5}, {{1, 1}, 4.5}};
  EXPECT_DOUBLE_EQ(predict_remaining_seconds(c, 50, 350, 1.0, render), 50 + 200 + 200 + 500);
  EXPECT_EQ(predict_remaining_seconds(c, 350, 350, 1.0, render), 0);
  EXPECT_EQ(phase_end(c, 50, 350), 100);
  EXPECT_EQ(phase_end(c, 200, 350), 250);
  EXPECT_EQ(phase_end(c, 260, 350), 350);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 0.01);
  for (int trial = 0; trial < 300; ++trial) {
    c.num_downscales = int(rng() % 4), c.resolution_schedule = 1 + int(rng() % 500);
    c.sh_degree = int(rng() % 4), c.sh_degree_interval = 1 + int(rng() % 700);
    const int64_t total = 1 + rng() % 3000, done = rng() % total;
    std::map<Phase, double> times;
    for (int f : {1, 2, 4, 8})
      for (int d = 0; d <= 3; ++d) times[{f, d}] = u(rng);
    const double rate = u(rng);
    EXPECT_NEAR(predict_remaining_seconds(c, done, total, rate, times), view_by_view(c, done, total, rate, times),
                1e-9 * double(total))
        << "trial " << trial;
  }
}

TEST(TrainingEta, TheLineSaysWhenItDoesNotKnow) {
  EXPECT_EQ(format_eta(-1), "--");
  EXPECT_EQ(format_eta(83.4), "1m23s");
  EXPECT_EQ(format_eta(0), "0m00s");
}

// The forecast against counts written out by hand: cycles of 100 views, 1.5× a cycle, the
// current cycle (views 100–199) began at 1,000 Gaussians and holds 1,200 at view 130.
TEST(TrainingEta, GrowthForecastIsAStepPerCycleUntilDensificationStops) {
  GrowthForecast f{.cycle = 100, .grows_until = 350, .factor = 1.5, .start_count = 1000, .count_now = 1200};
  EXPECT_DOUBLE_EQ(f.relative_count(130, 130), 1500.0 / 1200);  // this cycle ends at 1,500
  EXPECT_DOUBLE_EQ(f.relative_count(130, 199), 1500.0 / 1200);
  EXPECT_DOUBLE_EQ(f.relative_count(130, 200), 2250.0 / 1200);                   // the next one at 2,250
  EXPECT_DOUBLE_EQ(f.relative_count(130, 300), 2250.0 * std::sqrt(1.5) / 1200);  // half of it before 350
  EXPECT_DOUBLE_EQ(f.relative_count(130, 420), 2250.0 * std::sqrt(1.5) / 1200);  // none of it
  EXPECT_EQ(f.next_change(130), 200);
  EXPECT_EQ(f.next_change(200), 300);
  // Measured at a mean of 600 Gaussians, the rate stands for half the count now.
  GrowthForecast measured = f;
  measured.rate_count = 600;
  EXPECT_DOUBLE_EQ(measured.relative_count(130, 130), 1500.0 / 600);
  EXPECT_DOUBLE_EQ(measured.relative_count(130, 250), 2250.0 / 600);
  // A cycle that has already grown past its forecast holds at the count now.
  f.count_now = 1800;
  EXPECT_DOUBLE_EQ(f.relative_count(130, 150), 1.0);
  EXPECT_DOUBLE_EQ(f.relative_count(130, 250), 1.5);
  // After densification stops the count stays, even where it fell in the cycle.
  GrowthForecast late{.cycle = 100, .grows_until = 350, .factor = 1.5, .start_count = 2000, .count_now = 1800};
  EXPECT_DOUBLE_EQ(late.relative_count(360, 380), 1.0);
  EXPECT_DOUBLE_EQ(late.relative_count(360, 520), 1.0);
  // The count the cycle began with unknown (a resumed run): taken as the count now.
  GrowthForecast resumed{.cycle = 100, .grows_until = 1000, .factor = 2, .start_count = 0, .count_now = 500};
  EXPECT_DOUBLE_EQ(resumed.relative_count(150, 160), 2.0);
  // Before the warm-up ends (view 250) nothing grows; the cycle it ends in does, from then on.
  GrowthForecast warm{
      .cycle = 100, .grows_from = 250, .grows_until = 1000, .factor = 2, .start_count = 100, .count_now = 100};
  EXPECT_DOUBLE_EQ(warm.relative_count(10, 250), 1.0);
  EXPECT_DOUBLE_EQ(warm.relative_count(10, 251), 2.0);
  EXPECT_DOUBLE_EQ(warm.relative_count(10, 300), 4.0);
  EXPECT_EQ(warm.next_change(10), 100);
  EXPECT_EQ(warm.next_change(200), 251);
  EXPECT_EQ(warm.next_change(251), 300);
  // No cycles: no growth.
  EXPECT_DOUBLE_EQ(GrowthForecast{}.relative_count(10, 1000), 1.0);
}

// With growth, every view's cost is the schedule's cost times the count foreseen for it, here
// summed by hand over the segments where both are constant.
TEST(TrainingEta, PredictionScalesEachViewByTheCountForeseenForIt) {
  TrainConfig c;
  c.num_downscales = 1, c.resolution_schedule = 150;  // 1/2 size for views 0–149
  c.sh_degree = 0;
  const std::map<Phase, double> render{{{2, 0}, 0.5}, {{1, 0}, 2.5}};
  const GrowthForecast f{.cycle = 100, .grows_until = 1000, .factor = 2, .start_count = 100, .count_now = 100};
  // Views 50–99: 1.0 s × 2; 100–149: 1.0 × 4; 150–199: (1.0 + 2.0) × 4; 200–249: 3.0 × 8.
  EXPECT_DOUBLE_EQ(predict_remaining_seconds(c, 50, 250, 1.0, render, f), 50 * 2 + 50 * 4 + 50 * 12 + 50 * 24);
  // Without a forecast, the schedule alone.
  EXPECT_DOUBLE_EQ(predict_remaining_seconds(c, 50, 250, 1.0, render), 100 * 1 + 100 * 3);
}

TEST(TrainingEta, APhaseWithoutARenderTimeIsALogicError) {
  TrainConfig c;
  c.num_downscales = 1, c.resolution_schedule = 10, c.sh_degree = 0;
  EXPECT_THROW(predict_remaining_seconds(c, 0, 20, 1.0, {{{2, 0}, 0.1}}), std::logic_error);
}

// A real trainer on a made-up clock where a view costs 10 ms at 1/2 size and degree 0 and
// more by its phase's render time over that phase's, with a timer that answers those render
// times (2 ms at 1/2 size, 8 at full size, 1 more per SH degree) and, like a real one, adds
// them to the clock: the estimate is the clock's exact answer.
TEST(TrainingEta, EstimateIsExactWhenViewsCostWhatTheModelSays) {
  const TrainingData data = synthetic_training_data(6, 64, 48, 5);
  TrainConfig c = short_schedule(120);
  c.num_downscales = 1, c.resolution_schedule = 60;  // 1/2 size for views 0–59
  c.sh_degree = 1, c.sh_degree_interval = 100;       // degree 1 from view 100
  c.distractors.enabled = false;
  c.densify.warmup = 1000;  // no refinement: a constant count, no re-timing in between
  Trainer trainer(data, c);
  double clock = 0;
  int timings = 0;
  auto render = [](int width, int degree) { return (width == 64 ? 0.008 : 0.002) + 0.001 * degree; };
  auto timer = [&](const GaussianView&, const Camera& camera, const RasterSettings& rs) {
    const double seconds = render(camera.width, rs.active_sh_degree);
    clock += seconds, ++timings;
    return seconds;
  };
  TrainingEta eta(c, 0, c.iterations, timer);
  // Views 0–59: 10 ms; 60–99: 16 ms; 100–119: 17 ms.
  auto cost = [&](int64_t v) { return 0.010 + render(v < 60 ? 32 : 64, c.sh_degree_at(v)) - render(32, 0); };
  std::vector<double> at(c.iterations + 1, 0.0);  // the clock after each view
  std::vector<double> estimate(c.iterations + 1, 0.0);
  for (int64_t v = 1; v <= c.iterations; ++v) {
    trainer.step();
    clock += cost(v - 1);
    eta.observe(trainer, v, clock);
    at[v] = clock;
    estimate[v] = eta.remaining(v);
    if (v < 1 + TrainingEta::kMinWindow) {
      EXPECT_LT(estimate[v], 0) << "view " << v;
    }
  }
  // The first phase's rate, from view 21 on, then the shifted one after each change, then
  // the measured one of the phase.
  for (int64_t v : {21, 40, 59}) EXPECT_NEAR(estimate[v], (60 - v) * 0.010 + 40 * 0.016 + 20 * 0.017, 1e-9) << v;
  for (int64_t v : {61, 80, 99}) EXPECT_NEAR(estimate[v], (100 - v) * 0.016 + 20 * 0.017, 1e-9) << "view " << v;
  for (int64_t v : {100, 110, 119}) EXPECT_NEAR(estimate[v], (120 - v) * 0.017, 1e-9) << "view " << v;
  // Timed at the start (three phases, once more each the first time), at view 60 (the phase
  // left and the two to come) and at view 100 (the phase left and the last).
  constexpr int k = TrainingEta::kTimings;
  EXPECT_EQ(timings, 3 * (k + 1) + 3 * k + 2 * k);
  EXPECT_NEAR(eta.timing_seconds(),
              (k + 1) * (0.002 + 0.008 + 0.009) + k * (0.002 + 0.008 + 0.009) + k * (0.008 + 0.009), 1e-12);
  // metrics.json's record: the estimate at 10 % (view 12, no rate yet: the first with one,
  // view 21), 25 % (view 30) and 50 % (view 60), against the clock's time left.
  const nlohmann::json acc = eta.accuracy(at[c.iterations]);
  ASSERT_EQ(acc.size(), 3u);
  EXPECT_EQ(acc[0]["views_done"], 21);
  EXPECT_EQ(acc[1]["views_done"], 30);
  EXPECT_EQ(acc[2]["views_done"], 60);
  EXPECT_NEAR(acc[1]["predicted_seconds"].get<double>(), 30 * 0.010 + 40 * 0.016 + 20 * 0.017, 1e-9);
  EXPECT_NEAR(acc[1]["actual_seconds"].get<double>(), at[c.iterations] - at[30], 1e-12);
}

// On a real trainer that densifies in cycles of 40 views: the forecast's start count is the
// count each cycle began with, and its factor the last complete reset cycle's growth (from
// view 80 on: the first cycle, views 0–39, is not one).
TEST(TrainingEta, TheForecastTakesTheLastCompleteCyclesGrowth) {
  const TrainingData data = synthetic_training_data(6, 64, 48, 5);
  TrainConfig c = short_schedule(130);
  c.distractors.enabled = false;
  c.densify.warmup = 5, c.densify.refine_every = 10, c.densify.reset_alpha_every = 4;
  c.densify.stop_split_at = 130;
  c.densify.cull_scale = c.densify.cull_screen_size = 1e9f;  // the reset must not empty this small scene
  Trainer trainer(data, c);
  double clock = 0;
  TrainingEta eta(c, 0, c.iterations, [](const GaussianView&, const Camera&, const RasterSettings&) { return 0.0; });
  std::vector<double> count(c.iterations + 1, double(trainer.gaussians().size()));
  for (int64_t v = 1; v <= c.iterations; ++v) {
    trainer.step();
    clock += 0.01;
    eta.observe(trainer, v, clock);
    count[v] = double(trainer.gaussians().size());
    const GrowthForecast& f = eta.growth();
    ASSERT_EQ(f.cycle, 40);
    EXPECT_EQ(f.count_now, count[v]);
    // The cycle of view v began at view 40·k, whose count was read after the step before it.
    const int64_t k = v / 40;
    EXPECT_EQ(f.start_count, k == 0 ? count[0] : count[40 * k]) << "view " << v;
    const double expected = k <= 1 ? TrainingEta::kCycleGrowth : count[40 * k] / count[40 * (k - 1)];
    EXPECT_DOUBLE_EQ(f.factor, expected) << "view " << v;
  }
  // The case is not vacuous: the cycles changed the count.
  EXPECT_NE(count[40], count[0]);
  EXPECT_NE(count[80], count[40]);
}

}  // namespace
}  // namespace desplat::test
