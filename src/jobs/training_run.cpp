// desplat_train's job: scene → trainer → progress, evaluation, checkpoints, outputs.
#include "desplat/jobs/training_run.hpp"

#include "desplat/core/statistics.hpp"
#include "desplat/core/stopwatch.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/jobs/report.hpp"
#include "jobs/text_format.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/checkpoint.hpp"
#include "desplat/raster/composite.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/eval/mask_metrics.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/sfm/sfm.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "desplat/train/transient_probe.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

using Clock = std::chrono::steady_clock;

std::string format_duration(double s) {
  char buf[32];
  const int total = int(std::max(0.0, s));
  if (total >= 3600) std::snprintf(buf, sizeof buf, "%dh%02dm", total / 3600, total / 60 % 60);
  else std::snprintf(buf, sizeof buf, "%dm%02ds", total / 60, total % 60);
  return buf;
}

// Whether a step that took the views seen from `before` to `after` passed a multiple of
// `every` (> 0): with a batch of views a step advances by more than one.
bool reaches_multiple(int64_t before, int64_t after, int64_t every) { return after / every > before / every; }

// One progress line: rewritten in place on a terminal, printed every `log_every` steps
// otherwise.
class Progress {
 public:
  Progress(int64_t total, int log_every) : total_(total), log_every_(log_every), tty_(isatty(fileno(stdout))) {}
  void update(const StepStats& s, double elapsed, int64_t done_this_run) {
    const int64_t step = s.step + s.views;
    const bool due = tty_ ? (Clock::now() - last_ > std::chrono::milliseconds(200) || step == total_)
                          : (reaches_multiple(s.step, step, std::max(1, log_every_)) || step == total_);
    if (!due) return;
    last_ = Clock::now();
    const double rate = done_this_run / std::max(elapsed, 1e-9);
    const double eta = (total_ - step) / std::max(rate, 1e-9);
    char line[256];
    std::snprintf(line, sizeof line, "%6lld/%lld %3d%% ETA %s  loss %.4f  psnr %.2f  %zu Gaussians  %.2f it/s",
                  (long long)step, (long long)total_, int(100 * step / total_), format_duration(eta).c_str(), s.loss,
                  s.psnr, s.gaussians, rate);
    if (tty_) {
      const int width = 20, filled = int(width * step / total_);
      std::printf("\r[%s%s] %s\033[K", std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), line);
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

json metrics_json(const std::vector<ViewMetrics>& m) {
  json per = json::array();
  double psnr_sum = 0, ssim_sum = 0, right_psnr_sum = 0, right_ssim_sum = 0;
  for (const ViewMetrics& v : m) {
    per.push_back({{"name", v.name}, {"psnr", v.psnr}, {"ssim", v.ssim}, {"protocol", to_string(v.protocol)},
                   {"psnr_right_half", v.psnr_right_half}, {"ssim_right_half", v.ssim_right_half}});
    // Which look the Photo Tourism fit started from (a training view's name, or "mean").
    if (!v.look.start.empty()) per.back()["look_start"] = v.look.start;
    psnr_sum += v.psnr, ssim_sum += v.ssim;
    right_psnr_sum += v.psnr_right_half, right_ssim_sum += v.ssim_right_half;
  }
  // Without test views there is no mean: null, not a PSNR of 0.
  if (m.empty()) return {{"views", per}, {"mean_psnr", nullptr}, {"mean_ssim", nullptr}, {"count", 0}};
  const double n = double(m.size());
  return {{"views", per},
          {"mean_psnr", psnr_sum / n},
          {"mean_ssim", ssim_sum / n},
          {"count", m.size()},
          {"protocol", to_string(m.front().protocol)},
          // Every model's right halves: compares models with and without per-image embeddings.
          {"mean_psnr_right_half", right_psnr_sum / n},
          {"mean_ssim_right_half", right_ssim_sum / n}};
}

// --effects auto's evidence, for config.json and metrics.json.
json effects_evidence_json(const EffectsEvidence& ev, const std::vector<std::string>& reasons) {
  json views = json::array();
  for (const ViewEvidence& v : ev.views)
    views.push_back({{"name", v.name}, {"samples", v.samples}, {"log2_gain", v.log2_gain},
                     {"open_top_share", v.open_top_share}});
  return {{"reasons", reasons},
          {"judged_views", ev.judged_views},
          {"exposure_spread_stops", ev.exposure_spread_stops},
          {"white_balance_spread", ev.white_balance_spread},
          {"open_top_share", ev.open_top_share},
          {"views", views}};
}

// The transient probe's evidence: per training view, the share of its frame in view-specific areas.
json transient_evidence_json(const TransientEvidence& te, const TrainingData& data) {
  json views = json::array();
  for (size_t v = 0; v < te.view_share.size() && v < data.train.size(); ++v)
    views.push_back({{"name", data.train[v].name}, {"view_specific_share", te.view_share[v]}});
  return {{"reason", te.reason},
          {"judged_views", te.judged_views},
          {"views_with_transients", te.views_with_transients},
          {"transients", te.transients},
          {"views", views}};
}

// Distractor-mask quality against the scene's ground truth; null without masks.
json mask_json(const MaskMetrics& m) {
  if (m.views.empty()) return nullptr;
  json per = json::array();
  for (const ViewMaskMetrics& v : m.views)
    per.push_back({{"name", v.name},
                   {"iou", v.score.iou},
                   {"predicted_fraction", v.score.predicted_fraction},
                   {"truth_fraction", v.score.truth_fraction}});
  return {{"views", per},
          {"mean_iou", m.mean_iou},
          {"occluded_views", m.occluded_views},
          {"mean_clean_view_false_positive", m.mean_clean_view_false_positive},
          {"clean_views", m.clean_views}};
}

// Parameter memory in MB (float32), the "model size" of the paper's Tables A3/A4.
double parameter_mb(const TrainableGaussians& g) {
  size_t floats = 0;
  for (int k = 0; k < kParamGroups; ++k) floats += g.param(ParamGroup(k)).size();
  return double(floats) * sizeof(float) / (1024.0 * 1024.0);
}

// Sizes and memory of both kinds of Gaussians (the paper's Tables A3/A4).
json model_cost(const Trainer& t) {
  json per_view = json::array();
  double distractor_mb = 0;
  size_t nonempty = 0;
  for (size_t v = 0; v < t.distractors().size(); ++v) {
    const TrainableGaussians& d = t.distractors()[v];
    per_view.push_back({{"name", t.data().train[v].name}, {"count", d.size()}});
    distractor_mb += parameter_mb(d);
    nonempty += d.size() > 0;
  }
  return {{"static_gaussians", t.gaussians().size()},
          {"static_mb", parameter_mb(t.gaussians())},
          {"distractor_gaussians", t.distractor_count()},
          {"distractor_mb", distractor_mb},
          {"views_with_distractors", nonempty},
          {"distractors_per_view", per_view}};
}

// What SfM made of the user's photos, including every file and photo it left out.
json sfm_json(const sfm::SfmResult& r) {
  json skipped = json::array(), unregistered = json::array(), attempts = json::array();
  for (const sfm::SfmAttempt& a : r.attempts)
    attempts.push_back({{"step", a.step}, {"settings", a.settings}, {"registered", a.registered},
                        {"points", a.points}, {"seconds", a.seconds}});
  for (const sfm::SkippedFile& f : r.skipped) skipped.push_back({{"file", f.path.generic_string()}, {"reason", f.reason}});
  for (const sfm::SkippedFile& f : r.unregistered)
    unregistered.push_back({{"photo", f.path.generic_string()}, {"reason", f.reason}});
  return {{"photos", r.num_photos},
          {"registered", r.num_registered},
          {"points", r.num_points},
          {"mean_track_length", r.mean_track_length},
          {"mean_reprojection_error_px", r.mean_reprojection_error},
          {"models", r.num_models},
          {"seconds", r.seconds},
          {"cameras", r.cameras.reason},
          {"matching", r.matcher_reason},
          {"attempts", attempts},
          {"warning", r.warning},
          {"skipped_files", skipped},
          {"unregistered_photos", unregistered}};
}

}  // namespace

TrainingData load_training_data(const Scene& scene) {
  TrainingData data;
  data.points = scene.points_xyz;
  data.colors = scene.points_rgb;
  data.normalization = scene.normalization;
  std::vector<TrainView> views(scene.views.size());
  std::vector<uint8_t> rounded(scene.views.size(), 0);  // the photo had values 8 bits do not hold
  std::string error;
#pragma omp parallel for schedule(dynamic)
  for (size_t i = 0; i < scene.views.size(); ++i) {
    try {
      // Held in 8 bits (a quarter of float's memory): exact for 8-bit photos and the loader's
      // 8-bit cache; deeper files are rounded, and said so below (docs/METHOD.md §6).
      const FloatImage photo = load_view_image(scene, i);
      views[i] = {scene.views[i].name, scene.views[i].camera, to_bytes(photo), {}};
      for (size_t k = 0; k < photo.pixels.size() && !rounded[i]; ++k)
        rounded[i] = byte_to_float(views[i].image.pixels[k]) != photo.pixels[k];
      if (!scene.views[i].user_mask_path.empty()) {
        const std::vector<float> keep = load_view_keep_mask(scene, i);  // exactly 0 or 1
        views[i].keep.assign(keep.begin(), keep.end());
        // What the mask hides is never read: zero it, so no rule can use it by accident.
        for (size_t p = 0; p < views[i].keep.size(); ++p)
          if (views[i].keep[p] == 0) views[i].image.pixels[3 * p] = views[i].image.pixels[3 * p + 1] = views[i].image.pixels[3 * p + 2] = 0;
      }
    } catch (const std::exception& e) {
#pragma omp critical
      error = e.what();
    }
  }
  if (!error.empty()) throw SceneError(error);
  if (const auto n = std::count(rounded.begin(), rounded.end(), 1); n > 0) {
    const std::string first = scene.views[size_t(std::find(rounded.begin(), rounded.end(), 1) - rounded.begin())].name;
    const std::string message = std::to_string(n) + " of " + std::to_string(rounded.size()) + " photos (first: " + first +
                                ") hold more than 8 bits per channel or values outside [0, 1]; training rounds them "
                                "to 8 bits, clamped to [0, 1]";
    report_warning(scene.on_warning, message);
  }
  std::vector<int32_t> train_index(views.size(), -1);  // scene view → index into data.train
  for (size_t i = 0; i < views.size(); ++i) {
    if (!scene.views[i].is_test) train_index[i] = int32_t(data.train.size());
    (scene.views[i].is_test ? data.test : data.train).push_back(std::move(views[i]));
  }
  // The tracks, for transient_points (train/transient_points.hpp).
  if (scene.point_views.size() == scene.points_xyz.size() && scene.point_track_images.size() == scene.points_xyz.size()) {
    data.point_track_images = scene.point_track_images;
    data.point_train_views.resize(scene.point_views.size());
    for (size_t p = 0; p < scene.point_views.size(); ++p)
      for (const uint32_t v : scene.point_views[p])
        if (v < train_index.size() && train_index[v] >= 0) data.point_train_views[p].push_back(train_index[v]);
  }
  return data;
}

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

namespace {

// The first `shown` items joined by `separator`, then "and N more": a long list of settings
// would bury the first ones, which name the problem.
std::string first_items(const std::vector<std::string>& items, size_t shown, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < std::min(items.size(), shown); ++i) out += (i ? separator : "") + items[i];
  if (items.size() > shown) out += separator + "and " + std::to_string(items.size() - shown) + " more";
  return out;
}

// --resume continues the model with the settings it was trained with (`trained_with`, from
// config.json): a forgotten --preset or --config must not silently train the rest of the run
// differently. The length of the run, the threads and the kernels' instruction set may change
// (the last two move results by float rounding at most); they come from the command line or
// config file when named there. Any other setting named there (`asked` is what it gives) must
// agree with the record, or the resume is refused naming every setting that differs.
TrainConfig settings_to_resume(const TrainConfig& trained_with, const TrainConfig& asked, const TrainingData& data,
                               const TrainingRunOptions& opt, const json& config_overrides, const json& resumed_run,
                               const fs::path& record) {
  const bool settings_named = opt.preset || !opt.config.empty() || (opt.effects && *opt.effects != "auto") ||
                              opt.seed || opt.batch || opt.static_only || opt.distractors_per_view || opt.no_distractor_density ||
                              opt.no_regularization;
  if (settings_named) {
    const std::vector<std::string> differ = config_differences(effective_config(asked, data), trained_with, record.string(),
                                                               {"iterations", "threads", "kernel_isa"});
    if (!differ.empty()) {
      const std::string list = first_items(differ, 6, "; ");
      throw std::invalid_argument("--resume continues the model with the settings it was trained with, and this "
                                  "command changes " + std::to_string(differ.size()) + " of them: " + list +
                                  ". Resume without settings options (the run was started with --preset " +
                                  resumed_run.value("preset", std::string("default")) + " and effects " +
                                  resumed_run.value("effects", std::string("unrecorded")) +
                                  "), or start again with --overwrite to train with new ones");
    }
  }
  TrainConfig out = trained_with;
  if (opt.iterations || config_overrides.contains("iterations")) out.iterations = asked.iterations;
  if (opt.threads || config_overrides.contains("threads")) out.threads = asked.threads;
  if (config_overrides.contains("kernel_isa")) out.kernel_isa = asked.kernel_isa;
  return out;
}

}  // namespace

int run_training(const TrainingRunOptions& opt, const std::atomic<bool>& stop_requested) {
  if (opt.resume && opt.overwrite) throw std::invalid_argument("--resume and --overwrite contradict each other");
  if (!opt.resume) {
    const ModelFolder earlier(opt.out_dir);
    const std::vector<fs::path> outputs = earlier.existing_training_outputs();
    if (!outputs.empty() && !opt.overwrite) {
      std::string names;
      for (const fs::path& p : outputs) names += (names.empty() ? "" : ", ") + p.filename().string();
      throw std::invalid_argument(opt.out_dir.string() + " already holds a training run's outputs (" + names +
                                  "): continue it with --resume, replace them with --overwrite, or choose "
                                  "another --out");
    }
    if (opt.overwrite) earlier.remove_training_outputs();
  }
  fs::create_directories(opt.out_dir);
  fs::path data_dir = opt.data_dir;
  json sfm_summary;  // null unless this run ran SfM
  if (!opt.images_dir.empty()) {
    sfm::SfmOptions sfm_options;
    sfm_options.images = opt.images_dir;
    sfm_options.out = opt.out_dir / "sfm";
    sfm_options.overwrite = true;
    sfm_options.on_progress = sfm::terminal_progress(stdout, isatty(fileno(stdout)));
    const sfm::SfmResult r = sfm::run_sfm(sfm_options);
    std::printf("SfM: %d of %d photos registered, %d points, mean track length %.2f, mean reprojection error %.2f px "
                "(%.0f s)\n",
                r.num_registered, r.num_photos, r.num_points, r.mean_track_length, r.mean_reprojection_error, r.seconds);
    std::printf("%s%s", sfm::describe_attempts(r).c_str(), sfm::describe_lost_photos(r).c_str());
    sfm_summary = sfm_json(r);
    data_dir = sfm_options.out;
  }

  const std::string preset = opt.preset.value_or("default");
  TrainConfig config = preset_config(preset);
  json j = json::object();  // the --config settings (file or text)
  if (!opt.config.empty()) {
    const bool inline_text = opt.config.front() == '{';
    const std::string source = inline_text ? "--config text" : "config file " + opt.config;
    std::string text = opt.config;
    if (!inline_text) {
      std::ifstream f(opt.config);
      if (!f) throw std::invalid_argument("cannot read config file " + opt.config);
      text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    }
    try {
      j = json::parse(text);
    } catch (const json::exception& e) {
      throw std::invalid_argument(source + " is not valid JSON: " + e.what());
    }
    try {
      config = config_from_json(j, config);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(source + ": " + e.what());
    }
  }
  if (opt.iterations) config.iterations = *opt.iterations;
  if (opt.seed) config.seed = *opt.seed;
  if (opt.threads) config.threads = *opt.threads;
  if (opt.batch) config.batch = *opt.batch;
  if (config.iterations < 1) throw std::invalid_argument("--iterations must be at least 1");
  if (opt.static_only && opt.effects && *opt.effects != "none")
    throw std::invalid_argument("--static-only and --effects " + *opt.effects + " contradict each other");
  if (opt.static_only) config.distractors.enabled = false;
  // --effects defaults to auto; --static-only means none, and --preset paper keeps the
  // authors' set (distractors only) unless --effects says otherwise.
  const std::string effects = opt.effects.value_or(opt.static_only ? "none" : preset == "paper" ? "" : "auto");
  const bool auto_effects = effects == "auto";
  if (!effects.empty() && !auto_effects) Effects::parse(effects).apply(config);
  if (opt.distractors_per_view) {
    config.distractors.initial_count = *opt.distractors_per_view;
    config.distractors.reference_pixels = 0;  // exactly that many, whatever the image size
  }
  if (opt.no_distractor_density) config.distractors.density_control = false;
  if (opt.no_regularization) config.distractors.regularize = false;

  SceneOptions scene_options;
  scene_options.downscale = opt.downscale;
  scene_options.split = opt.split;
  scene_options.masks_dir = opt.masks_dir;
  const Scene scene = load_colmap_scene(data_dir, scene_options);
  const ModelFolder model(opt.out_dir);
  const SceneRecipe recipe = SceneRecipe::of(scene, data_dir, scene_options);
  json resumed_run = json::object();  // the resumed model's run record (config.json "run")
  std::optional<TrainConfig> trained_with;  // --resume: the settings the model was trained with
  if (opt.resume) {
    if (!model.has_checkpoint())
      throw std::invalid_argument("--resume: no checkpoint at " + model.checkpoint_path().string());
    const ModelFolder::Config trained = model.read_config();
    resumed_run = trained.run;
    trained_with = trained.train;
    if (!trained.unrecorded_settings.empty()) {
      // Said before anything trains: the rest of the run uses today's defaults for them.
      const std::vector<std::string>& missing = trained.unrecorded_settings;
      std::printf("warning: %s records no value for %zu setting%s (%s): it was written by an older desplat, and the "
                  "resumed run uses today's defaults for them\n",
                  model.config_path().c_str(), missing.size(), missing.size() == 1 ? "" : "s",
                  first_items(missing, 6, ", ").c_str());
    }
    // Continuing on other views or at another size would silently train another model.
    const std::string changed = trained.scene.difference(recipe);
    if (!changed.empty())
      throw std::invalid_argument("--resume: the scene is not the one " + opt.out_dir.string() +
                                  " was trained on: " + changed);
  }
  const TrainingData data = load_training_data(scene);
  json effects_evidence = nullptr;
  if (auto_effects && resumed_run.contains("effects")) {
    // A resumed run continues the model it resumes, with the effects it was trained with
    // (auto's probe is not repeated: it would take up to a minute to give the same answer).
    Effects::parse(resumed_run.at("effects").get<std::string>()).apply(config);
    effects_evidence = resumed_run.value("effects_evidence", json(nullptr));
    std::printf("--effects auto: %s, as this model was trained\n", Effects::of(config).to_string().c_str());
  } else if (auto_effects) {
    const EffectsEvidence ev = examine_effects(data);
    std::vector<std::string> why;
    Effects chosen = choose_effects(Effects::of(config), ev, why);
    json transients = nullptr;
    if (chosen.distractors) {
      // Distractors as configured (on by default) are kept only where a short static-only
      // probe, with the appearance and background just chosen, finds transients.
      Effects probe_set = chosen;
      probe_set.distractors = false;
      TrainConfig probe_config = config;
      probe_set.apply(probe_config);
      const TransientRules rules;
      std::printf("--effects auto: probing for transients (%d static-only steps at 1/%d resolution)\n",
                  rules.probe_steps,
                  data.train.empty() ? 1 : probe_factor(data.train[0].camera.width, data.train[0].camera.height, rules));
      const Stopwatch probe_clock;
      const std::optional<TransientEvidence> probed = probe_transients(data, probe_config, rules, &stop_requested);
      if (!probed) {
        std::printf("interrupted during the transient probe, before training started: no checkpoint was written\n");
        return 130;
      }
      const TransientEvidence& te = *probed;
      const double probe_seconds = probe_clock.seconds();
      chosen.distractors = te.transients;
      why.insert(why.begin(), std::string("distractors ") + (te.transients ? "on" : "off") + ": " + te.reason);
      transients = transient_evidence_json(te, data);
      transients["probe_seconds"] = probe_seconds;
      std::printf("--effects auto: the probe took %.1f s\n", probe_seconds);
    } else {
      why.insert(why.begin(), "distractors off: the preset and --config turn them off");
    }
    chosen.apply(config);
    std::printf("--effects auto: %s\n", chosen.to_string().c_str());
    for (const std::string& line : why) std::printf("  %s\n", line.c_str());
    effects_evidence = effects_evidence_json(ev, why);
    effects_evidence["transients"] = transients;
  }
  if (trained_with) config = settings_to_resume(*trained_with, config, data, opt, j, resumed_run, model.config_path());
  std::printf("scene %s: %zu training and %zu test views at %dx%d, %zu points\n", data_dir.c_str(), data.train.size(),
              data.test.size(), data.train.empty() ? 0 : data.train[0].camera.width,
              data.train.empty() ? 0 : data.train[0].camera.height, data.points.size());
  if (!scene.masks_dir.empty()) {
    const auto masked = std::count_if(scene.views.begin(), scene.views.end(),
                                      [](const SceneView& v) { return !v.user_mask_path.empty(); });
    std::printf("masks from %s for %ld of %zu views: their black pixels are ignored in training and metrics\n",
                scene.masks_dir.c_str(), static_cast<long>(masked), scene.views.size());
  }
  if (config.distractors.enabled)
    std::printf("DeSplat: %d distractor Gaussians per training view%s%s\n",
                data.train.empty() ? 0 : distractor_count_for(data.train[0].camera, config.distractors),
                config.distractors.density_control ? "" : ", no distractor density control",
                config.distractors.regularize ? "" : ", no opacity regularizers");
  else
    std::printf("static-only (Splatfacto baseline)\n");
  // Splatfacto's resolution schedule assumes 30k steps; a short run would silently end on
  // downscaled images and score poorly at full resolution.
  const int64_t full_resolution_from = config.full_resolution_from();
  if (full_resolution_from >= config.iterations)
    std::printf("warning: this run never trains at full resolution (the resolution schedule reaches it at step "
                "%lld of %lld); add {\"num_downscales\": 0} to --config or train longer\n",
                (long long)full_resolution_from, (long long)config.iterations);
  // The default waits for step 3,000 before seeding distractors (docs/METHOD.md §7): a
  // shorter run never grows a buffer onto an occluder its initial distractors missed.
  const DistractorSettings& ds = config.distractors;
  if (config.distractors.enabled && (ds.seed_uncovered || ds.reseed_starved_views) && ds.seed_after >= config.iterations)
    std::printf("warning: distractor seeding starts at step %d (distractors.seed_after), after this run's %lld steps; "
                "for a run this short use --preset fast, or add {\"distractors\": {\"seed_after\": 0}} to --config\n",
                ds.seed_after, (long long)config.iterations);

  if (config.appearance.enabled)
    std::printf("appearance model: embeddings of %d per training image and %d per Gaussian, MLP %d x %d; test views are "
                "scored by the Photo Tourism protocol (embedding fitted on the left half, %d steps from %s; scored on the "
                "right)\n",
                config.appearance.image_dim, config.appearance.feature_dim(), config.appearance.hidden_layers,
                config.appearance.hidden_width, config.appearance.test_steps,
                config.appearance.test_start_from_best_look ? "the training look that fits it best" : "the mean look");
  if (config.background.enabled)
    std::printf("background model: embeddings of %d per training image, MLP %d x %d to spherical harmonics of degree %d; "
                "test views are scored by the Photo Tourism protocol (embeddings fitted on the left half, %d steps from "
                "%s)\n",
                config.background.image_dim, config.background.hidden_layers, config.background.hidden_width,
                config.background.sh_degree, config.appearance.test_steps,
                config.appearance.test_start_from_best_look ? "the training look that fits it best" : "the mean look");
  const json run_json = {{"static_only", opt.static_only},
                         {"preset", resumed_run.value("preset", preset)},
                         {"effects", Effects::of(config).to_string()},
                         {"effects_chosen_by", auto_effects ? "auto" : "the command line and preset"},
                         {"effects_evidence", effects_evidence}};
  Trainer trainer(data, config);
  // The trainer's configuration is the effective one (e.g. a static-only model keeps every
  // sparse point): that is what config.json records.
  config = trainer.config();
  model.write_config({config, recipe, run_json, {}});
  if (config.transient_points.action != TransientPointAction::keep)
    std::printf("transient sparse points (%s): %lld of %zu, %lld distractors seeded from them\n",
                to_string(config.transient_points.action).c_str(), (long long)trainer.transient_point_count,
                data.points.size(), (long long)trainer.transient_seeded);
  if (const CameraPath& path = trainer.camera_path(); !path.empty())
    std::printf("camera path: %zu segments between consecutive training views (%zu longer than %.2f x the median "
                "scene depth skipped); static Gaussians within %.4f world units of it, or in a blind gap (within "
                "%.2f x a step of it, in front, in neither photo) are culled\n",
                path.from.size(), path.skipped_segments, double(config.densify.camera_path.max_segment), path.radius,
                path.blind_gap);
  const fs::path ckpt_path = model.checkpoint_path();
  auto save = [&] { model.write_checkpoint(trainer, {{"run", run_json}}); };
  if (opt.resume) {
    restore_training_checkpoint(trainer, model.read_checkpoint());
    std::printf("resumed from %s at step %lld\n", ckpt_path.c_str(), (long long)trainer.current_step());
  }

  json history = json::array();
  const bool has_masks = std::any_of(scene.views.begin(), scene.views.end(),
                                     [](const SceneView& v) { return !v.mask_path.empty(); });
  std::vector<double> t_fwd, t_bwd, t_loss, t_opt, t_dist, t_look, t_sky, t_total, dist_share;
  std::vector<double> pairs, ns_forward, ns_forward_backward, visible_share;
  Progress progress(config.iterations, opt.log_every);
  const Stopwatch run_clock;
  const int64_t first = trainer.current_step();
  // The training curve for report.html: mean loss and PSNR over each interval, about 200 points.
  const int64_t curve_every = std::max<int64_t>(1, config.iterations / 200);
  double curve_loss = 0, curve_psnr = 0;
  int curve_steps = 0;
  while (trainer.current_step() < config.iterations) {
    if (stop_requested.load()) {
      save();
      progress.newline_if_tty();
      std::printf("interrupted at step %lld; checkpoint written to %s (continue with --resume)\n",
                  (long long)trainer.current_step(), ckpt_path.c_str());
      return 130;
    }
    const StepStats s = trainer.step();
    if (!s.distractor_refinements.empty()) history.push_back(distractor_refinement_json(s, trainer));
    if (config.downscale_at(s.step) == 1) {
      t_fwd.push_back(s.timings.forward), t_bwd.push_back(s.timings.backward);
      t_loss.push_back(s.timings.loss), t_opt.push_back(s.timings.optimizer);
      t_dist.push_back(s.timings.distractor), t_total.push_back(s.timings.total());
      t_look.push_back(s.timings.appearance);
      t_sky.push_back(s.timings.background);
      dist_share.push_back(s.timings.distractor / std::max(s.timings.total(), 1e-12));
      const double n_pairs = double(std::max<int64_t>(1, s.static_pairs));
      pairs.push_back(double(s.static_pairs));
      ns_forward.push_back(1e9 * s.timings.forward / n_pairs);
      ns_forward_backward.push_back(1e9 * (s.timings.forward + s.timings.backward) / n_pairs);
      visible_share.push_back(double(s.static_visible) / s.views / double(std::max<size_t>(1, s.gaussians)));
    }
    const double elapsed = run_clock.seconds();
    progress.update(s, elapsed, trainer.current_step() - first);
    const int64_t done = trainer.current_step(), before = s.step;
    curve_loss += s.loss, curve_psnr += std::min(s.psnr, 99.0), ++curve_steps;  // +inf PSNR: a perfect step
    if (reaches_multiple(before, done, curve_every) || done == config.iterations) {
      history.push_back({{"kind", "training"},
                         {"step", done},
                         {"wall_seconds", elapsed},
                         {"loss", curve_loss / curve_steps},
                         {"psnr", curve_psnr / curve_steps},
                         {"gaussians", s.gaussians},
                         {"distractor_gaussians", trainer.distractor_count()}});
      curve_loss = curve_psnr = 0, curve_steps = 0;
    }
    if (opt.eval_every > 0 && reaches_multiple(before, done, opt.eval_every) && done < config.iterations && !data.test.empty()) {
      json m = metrics_json(trainer.evaluate(data.test));
      json point = {{"kind", "evaluation"},
                    {"step", done},
                    {"wall_seconds", run_clock.seconds()},
                    {"mean_psnr", m["mean_psnr"]},
                    {"mean_ssim", m["mean_ssim"]},
                    {"gaussians", trainer.gaussians().size()},
                    {"distractor_gaussians", trainer.distractor_count()}};
      if (has_masks) point["mean_mask_iou"] = evaluate_distractor_masks(trainer, scene).mean_iou;
      history.push_back(point);
    }
    if (opt.checkpoint_every > 0 && reaches_multiple(before, done, opt.checkpoint_every) && done < config.iterations) save();
  }
  const double wall = run_clock.seconds();
  save();

  // Final evaluation and outputs.
  const std::vector<ViewMetrics> final_metrics = trainer.evaluate(data.test);
  for (const TrainView& v : data.test) {
    fs::path name = fs::path(v.name).replace_extension(".png");
    // A model with per-image appearance or background shows the test view in the look fitted
    // on its left half.
    const auto scored = std::find_if(final_metrics.begin(), final_metrics.end(),
                                     [&](const ViewMetrics& m) { return m.name == v.name; });
    const FloatImage render =
        trainer.render(v.camera, config.eval_background, scored != final_metrics.end() ? scored->look : ViewLook{});
    const FloatImage photo = to_float(v.image);
    write_image(opt.out_dir / "renders" / "test" / name, side_by_side({&photo, &render}));
  }
  // The paper's Fig. 2 for every training view: truth | static | distractor | composite | mask.
  if (config.distractors.enabled)
    for (size_t v = 0; v < data.train.size(); ++v)
      write_image(opt.out_dir / "renders" / "train" / fs::path(data.train[v].name).replace_extension(".png"),
                  layers_figure_row(to_float(data.train[v].image), trainer.render_layers(v, config.eval_background)));
  write_gaussian_ply(opt.out_dir / "point_cloud.ply", trainer.gaussians().params, data.normalization);
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  json metrics = metrics_json(final_metrics);
  metrics["step"] = trainer.current_step();
  metrics["gaussians"] = trainer.gaussians().size();
  metrics["mode"] = config.distractors.enabled ? "desplat" : "static-only";
  metrics["effects"] = {{"chosen", Effects::of(config).to_string()},
                        {"by", auto_effects ? "auto" : "the command line and preset"},
                        {"evidence", effects_evidence}};
  metrics["cost"] = model_cost(trainer);
  metrics["transient_points"] = {{"action", to_string(config.transient_points.action)},
                                 {"points", trainer.transient_point_count},
                                 {"seeded_distractors", trainer.transient_seeded}};
  const CameraPath& path = trainer.camera_path();
  metrics["camera_path"] = {{"segments", path.from.size()},
                            {"skipped_segments", path.skipped_segments},
                            {"median_scene_depth", path.median_depth},
                            {"radius", path.radius},
                            {"blind_gap", path.blind_gap},
                            {"culled_this_run", trainer.camera_path_culled},
                            {"culled_in_blind_gaps_this_run", trainer.camera_path_blind_gap_culled}};
  const MaskMetrics masks = evaluate_distractor_masks(trainer, scene);
  metrics["distractor_masks"] = mask_json(masks);
  if (!sfm_summary.is_null()) metrics["sfm"] = sfm_summary;
  metrics["history"] = history;
  metrics["wall_seconds_this_run"] = wall;
  metrics["peak_memory_mb"] = double(usage.ru_maxrss) / 1024.0;
  metrics["median_step_seconds_full_resolution"] = {{"forward", median(t_fwd)},
                                                     {"backward", median(t_bwd)},
                                                     {"loss", median(t_loss)},
                                                     {"optimizer_and_density", median(t_opt)},
                                                     {"distractor_branch", median(t_dist)},
                                                     {"appearance", median(t_look)},
                                                     {"background", median(t_sky)},
                                                     {"total", median(t_total)},
                                                     {"distractor_share", median(dist_share)},
                                                     {"steps_measured", t_fwd.size()},
                                                     // the static layer's render:
                                                     {"pairs", median(pairs)},
                                                     {"ns_per_pair_forward", median(ns_forward)},
                                                     {"ns_per_pair_forward_backward", median(ns_forward_backward)},
                                                     {"visible_share", median(visible_share)},
                                                     {"kernel_isa", kernel_isa_name(resolve_kernel_isa(config.kernel_isa))}};
  model.write_metrics(metrics);
  const std::string scores =
      final_metrics.empty() ? std::string("no test views to score (the split left none)")
                            : "test PSNR " + fixed(metrics["mean_psnr"].get<double>(), 2) + " dB, SSIM " +
                                  fixed(metrics["mean_ssim"].get<double>(), 4);
  std::printf("done: %lld steps in %s, %zu static + %zu distractor Gaussians; %s\n", (long long)trainer.current_step(),
              format_duration(wall).c_str(), trainer.gaussians().size(), trainer.distractor_count(), scores.c_str());
  if (!masks.views.empty())
    std::printf("distractor masks: mean IoU %.3f over %d occluded training views; %.2f%% false positives on %d clean views\n",
                masks.mean_iou, masks.occluded_views, 100 * masks.mean_clean_view_false_positive, masks.clean_views);
  const ReportResult report = write_report(opt.out_dir);
  if (!report.note.empty()) std::printf("report: %s\n", report.note.c_str());
  std::printf("outputs in %s: report.html (open it in a browser), metrics.json, renders/test/%s, point_cloud.ply, "
              "checkpoint.ckpt\n",
              fs::absolute(opt.out_dir).c_str(), config.distractors.enabled ? ", renders/train/" : "");
  return 0;
}

}  // namespace desplat
