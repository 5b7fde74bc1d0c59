// desplat_train's training loop: progress on stdout, the history metrics.json keeps, the
// per-step timings, periodic evaluation and checkpoints.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "desplat/core/stopwatch.hpp"
#include "desplat/eval/mask_metrics.hpp"
#include "desplat/jobs/training_eta.hpp"
#include "jobs/text_format.hpp"
#include "jobs/training_steps.hpp"

namespace desplat {
using json = nlohmann::json;

namespace {

using Clock = std::chrono::steady_clock;

// Whether a step that took the views seen from `before` to `after` passed a multiple of
// `every` (> 0): with a batch of views a step advances by more than one.
bool reaches_multiple(int64_t before, int64_t after, int64_t every) { return after / every > before / every; }

// One progress line: rewritten in place on a terminal, printed every `log_every` steps
// otherwise.
class Progress {
 public:
  Progress(int64_t total, int log_every) : total_(total), log_every_(log_every), tty_(isatty(fileno(stdout))) {}
  // `eta`: the time left as format_eta writes it.
  void update(const StepStats& s, double elapsed, int64_t done_this_run, const std::string& eta) {
    const int64_t step = s.step + s.views;
    const bool due = tty_ ? (Clock::now() - last_ > std::chrono::milliseconds(200) || step == total_)
                          : (reaches_multiple(s.step, step, std::max(1, log_every_)) || step == total_);
    if (!due) return;
    last_ = Clock::now();
    const double rate = done_this_run / std::max(elapsed, 1e-9);
    char line[256];
    std::snprintf(line, sizeof line, "%6lld/%lld %3d%% ETA %s  loss %.4f  psnr %.2f  %zu Gaussians  %.2f it/s",
                  (long long)step, (long long)total_, int(100 * step / total_), eta.c_str(), s.loss, s.psnr,
                  s.gaussians, rate);
    if (tty_) {
      const int width = 20, filled = int(width * step / total_);
      std::printf("\r[%s%s] %s\033[K", std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(),
                  line);
      if (step == total_) std::printf("\n");
    } else {
      std::printf("%s\n", line);
    }
    std::fflush(stdout);
  }
  void newline_if_tty() {
    if (tty_) std::printf("\n");
  }

 private:
  int64_t total_;
  int log_every_;
  bool tty_;
  Clock::time_point last_{};
};

// One distractor refinement for the history: per view, the buffer before and after, the
// growth budget, the high-gradient candidates, splits, duplicates, culls (idle_culled: by the
// idle cull, before growth), the summed alpha under max_alpha_sum and the
// distribution of mean gradient / threshold (docs/METHOD.md §7).
json distractor_refinement_json(const StepStats& s, const Trainer& trainer) {
  json views = json::array();
  for (const ViewRefinement& r : s.distractor_refinements)
    views.push_back({{"view", trainer.data().train[r.view].name},
                     {"before", r.before},
                     {"after", r.after},
                     {"budget", r.budget == kUnlimitedGrowth ? json(nullptr) : json(r.budget)},
                     {"high_gradient", r.report.high_gradient},
                     {"split", r.report.split},
                     {"duplicated", r.report.duplicated},
                     {"culled", r.report.culled},
                     {"idle_culled", r.idle},
                     {"held_back", r.report.held_back},
                     {"alpha_sum", r.alpha_sum},
                     {"gradient_ratio_bins", r.report.gradient_ratio_bins},
                     {"static_unexplained", trainer.view_static_unexplained[r.view]},
                     {"composite_unexplained", trainer.view_composite_unexplained[r.view]}});
  return {{"kind", "distractor_refinement"},
          {"step", s.step},
          {"gradient_ratio_bin_edges", {0.5, 1, 2, 4}},
          {"static_gaussians", s.gaussians},
          {"distractor_gaussians", trainer.distractor_count()},
          {"views", views}};
}

}  // namespace

TrainingRecord train_to_end(Trainer& trainer, const TrainingRunOptions& opt, const Scene& scene,
                            const std::function<void()>& save, const std::atomic<bool>& stop_requested) {
  TrainingRecord r;
  const TrainConfig& config = trainer.config();
  const TrainingData& data = trainer.data();
  const bool has_masks =
      std::any_of(scene.views.begin(), scene.views.end(), [](const SceneView& v) { return !v.mask_path.empty(); });
  Progress progress(config.iterations, opt.log_every);
  const Stopwatch run_clock;
  const int64_t first = trainer.current_step();
  TrainingEta eta(config, first, config.iterations);
  // The training curve for report.html: mean loss and PSNR over each interval, about 200 points.
  const int64_t curve_every = std::max<int64_t>(1, config.iterations / 200);
  double curve_loss = 0, curve_psnr = 0;
  int curve_steps = 0;
  int64_t interval_bytes = 0;  // this rank's collectives since the last curve point
  double interval_comm_seconds = 0;
  while (trainer.current_step() < config.iterations) {
    // The ranks stop together, at the same step, when any of them was asked to.
    if (any_rank(trainer.communicator(), stop_requested.load())) {
      save();
      progress.newline_if_tty();
      std::printf("interrupted at step %lld; checkpoint written to %s (continue with --resume)\n",
                  (long long)trainer.current_step(), ModelFolder(opt.out_dir).checkpoint_path().c_str());
      r.interrupted = true;
      return r;
    }
    const StepStats s = trainer.step();
    if (!s.distractor_refinements.empty()) r.history.push_back(distractor_refinement_json(s, trainer));
    if (config.downscale_at(s.step) == 1) {
      r.forward.push_back(s.timings.forward), r.backward.push_back(s.timings.backward);
      r.loss.push_back(s.timings.loss), r.optimizer.push_back(s.timings.optimizer);
      r.distractor.push_back(s.timings.distractor), r.total.push_back(s.timings.total());
      r.appearance.push_back(s.timings.appearance);
      r.background.push_back(s.timings.background);
      r.distractor_share.push_back(s.timings.distractor / std::max(s.timings.total(), 1e-12));
      const double n_pairs = double(std::max<int64_t>(1, s.static_pairs));
      r.pairs.push_back(double(s.static_pairs));
      r.ns_forward.push_back(1e9 * s.timings.forward / n_pairs);
      r.ns_forward_backward.push_back(1e9 * (s.timings.forward + s.timings.backward) / n_pairs);
      r.visible_share.push_back(double(s.static_visible) / s.views / double(std::max<size_t>(1, s.gaussians)));
    }
    r.comm_bytes.push_back(double(s.comm_bytes)), r.comm_seconds.push_back(s.comm_seconds);
    r.step_seconds.push_back(s.timings.total());
    const double elapsed = run_clock.seconds();
    eta.observe(trainer, trainer.current_step(), elapsed);
    progress.update(s, elapsed, trainer.current_step() - first, format_eta(eta.remaining(trainer.current_step())));
    const int64_t done = trainer.current_step(), before = s.step;
    curve_loss += s.loss, curve_psnr += std::min(s.psnr, 99.0), ++curve_steps;  // +inf PSNR: a perfect step
    interval_bytes += s.comm_bytes, interval_comm_seconds += s.comm_seconds;
    if (reaches_multiple(before, done, curve_every) || done == config.iterations) {
      r.history.push_back({{"kind", "training"},
                           {"step", done},
                           {"wall_seconds", elapsed},
                           {"loss", curve_loss / curve_steps},
                           {"psnr", curve_psnr / curve_steps},
                           {"gaussians", s.gaussians},
                           {"distractor_gaussians", trainer.distractor_count()},
                           {"comm_bytes", interval_bytes},
                           {"comm_seconds", interval_comm_seconds}});
      curve_loss = curve_psnr = 0, curve_steps = 0;
      interval_bytes = 0, interval_comm_seconds = 0;
    }
    if (opt.eval_every > 0 && reaches_multiple(before, done, opt.eval_every) && done < config.iterations &&
        !data.test.empty()) {
      json m = metrics_json(trainer.evaluate(data.test));
      json point = {{"kind", "evaluation"},
                    {"step", done},
                    {"wall_seconds", run_clock.seconds()},
                    {"mean_psnr", m["mean_psnr"]},
                    {"mean_ssim", m["mean_ssim"]},
                    {"gaussians", trainer.gaussians().size()},
                    {"distractor_gaussians", trainer.distractor_count()}};
      if (has_masks) {
        // Every view's distractors are needed, on rank 0: gathered for the score, then released.
        trainer.gather_to_root();
        point["mean_mask_iou"] = evaluate_distractor_masks(trainer, scene).mean_iou;
        trainer.keep_own_share();
      }
      r.history.push_back(point);
    }
    if (opt.checkpoint_every > 0 && reaches_multiple(before, done, opt.checkpoint_every) && done < config.iterations)
      save();
  }
  r.wall_seconds = run_clock.seconds();
  r.eta_accuracy = eta.accuracy(r.wall_seconds);
  r.eta_timing_seconds = eta.timing_seconds();
  return r;
}

}  // namespace desplat
