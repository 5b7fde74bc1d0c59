// desplat_train's outputs after training: the final evaluation, the renders, the static
// Gaussians as a PLY, metrics.json and report.html.
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <numeric>

#include "desplat/core/statistics.hpp"
#include "desplat/eval/mask_metrics.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/jobs/report.hpp"
#include "desplat/raster/composite.hpp"
#include "desplat/train/effects.hpp"
#include "jobs/text_format.hpp"
#include "jobs/training_steps.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

json metrics_json(const std::vector<ViewMetrics>& m) {
  json per = json::array();
  double psnr_sum = 0, ssim_sum = 0, right_psnr_sum = 0, right_ssim_sum = 0;
  for (const ViewMetrics& v : m) {
    per.push_back({{"name", v.name},
                   {"psnr", v.psnr},
                   {"ssim", v.ssim},
                   {"protocol", to_string(v.protocol)},
                   {"psnr_right_half", v.psnr_right_half},
                   {"ssim_right_half", v.ssim_right_half}});
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

namespace {

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
  return {{"static_gaussians", t.gaussians().size()},     {"static_mb", parameter_mb(t.gaussians())},
          {"distractor_gaussians", t.distractor_count()}, {"distractor_mb", distractor_mb},
          {"views_with_distractors", nonempty},           {"distractors_per_view", per_view}};
}

}  // namespace

void write_training_outputs(const Trainer& trainer, const TrainingRunOptions& opt, const RunInputs& inputs,
                            const ResolvedSettings& settings, const TrainingRecord& record) {
  const TrainConfig& config = trainer.config();
  const TrainingData& data = trainer.data();
  // Final evaluation (every rank scores its own test views), then the outputs, by rank 0.
  const std::vector<ViewMetrics> final_metrics = trainer.evaluate(data.test);
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  std::vector<double> peak_mb(size_t(trainer.ranks()), 0.0);  // each rank's peak resident memory
  peak_mb[size_t(trainer.rank())] = double(usage.ru_maxrss) / 1024.0;
  if (Communicator* comm = trainer.communicator()) comm->sum(std::span(peak_mb));
  if (trainer.rank() != 0) return;
  // Rank 0's own views are in memory; another rank's photo is read again, one at a time.
  auto photo_of = [&](const TrainView& v) {
    if (!v.image.pixels.empty()) return to_float(v.image);
    const auto at = std::find_if(inputs.scene.views.begin(), inputs.scene.views.end(),
                                 [&](const SceneView& sv) { return sv.name == v.name; });
    ByteImage photo;
    std::vector<uint8_t> keep;
    load_view_photo(inputs.scene, size_t(at - inputs.scene.views.begin()), photo, keep);
    return to_float(photo);
  };
  for (const TrainView& v : data.test) {
    fs::path name = fs::path(v.name).replace_extension(".png");
    // A model with per-image appearance or background shows the test view in the look fitted
    // on its left half.
    const auto scored = std::find_if(final_metrics.begin(), final_metrics.end(),
                                     [&](const ViewMetrics& m) { return m.name == v.name; });
    const FloatImage render =
        trainer.render(v.camera, config.eval_background, scored != final_metrics.end() ? scored->look : ViewLook{});
    const FloatImage photo = photo_of(v);
    write_image(opt.out_dir / "renders" / "test" / name, side_by_side({&photo, &render}));
  }
  // The paper's Fig. 2 for every training view: truth | static | distractor | composite | mask.
  if (config.distractors.enabled)
    for (size_t v = 0; v < data.train.size(); ++v)
      write_image(opt.out_dir / "renders" / "train" / fs::path(data.train[v].name).replace_extension(".png"),
                  layers_figure_row(photo_of(data.train[v]), trainer.render_layers(v, config.eval_background)));
  write_gaussian_ply(opt.out_dir / "point_cloud.ply", trainer.gaussians().params, data.normalization);
  json metrics = metrics_json(final_metrics);
  metrics["step"] = trainer.current_step();
  metrics["gaussians"] = trainer.gaussians().size();
  metrics["mode"] = config.distractors.enabled ? "desplat" : "static-only";
  metrics["effects"] = {{"chosen", Effects::of(config).to_string()},
                        {"by", settings.effects_chosen_by},
                        {"evidence", settings.effects_evidence}};
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
  const MaskMetrics masks = evaluate_distractor_masks(trainer, inputs.scene);
  metrics["distractor_masks"] = mask_json(masks);
  if (!inputs.sfm_summary.is_null()) metrics["sfm"] = inputs.sfm_summary;
  metrics["history"] = record.history;
  metrics["wall_seconds_this_run"] = record.wall_seconds;
  metrics["eta_accuracy"] = record.eta_accuracy;
  metrics["eta_timing_seconds"] = record.eta_timing_seconds;
  metrics["peak_memory_mb"] = peak_mb[0];
  metrics["ranks"] = {{"count", trainer.ranks()},
                      {"communicator", trainer.communicator() ? trainer.communicator()->kind() : "single process"},
                      {"peak_memory_mb", peak_mb}};
  // Rank 0's collectives: payload bytes and seconds per step, and their share of the step time.
  const double comm_total = std::accumulate(record.comm_seconds.begin(), record.comm_seconds.end(), 0.0),
               step_total = std::accumulate(record.step_seconds.begin(), record.step_seconds.end(), 0.0);
  metrics["communication"] = {{"median_bytes_per_step", median(record.comm_bytes)},
                              {"median_seconds_per_step", median(record.comm_seconds)},
                              {"total_bytes", std::accumulate(record.comm_bytes.begin(), record.comm_bytes.end(), 0.0)},
                              {"total_seconds", comm_total},
                              {"share_of_step_time", step_total > 0 ? comm_total / step_total : 0.0}};
  metrics["median_step_seconds_full_resolution"] = {
      {"forward", median(record.forward)},
      {"backward", median(record.backward)},
      {"loss", median(record.loss)},
      {"optimizer_and_density", median(record.optimizer)},
      {"distractor_branch", median(record.distractor)},
      {"appearance", median(record.appearance)},
      {"background", median(record.background)},
      {"total", median(record.total)},
      {"distractor_share", median(record.distractor_share)},
      {"steps_measured", record.forward.size()},
      // the static layer's render:
      {"pairs", median(record.pairs)},
      {"ns_per_pair_forward", median(record.ns_forward)},
      {"ns_per_pair_forward_backward", median(record.ns_forward_backward)},
      {"visible_share", median(record.visible_share)},
      {"kernel_isa", kernel_isa_name(resolve_kernel_isa(config.kernel_isa))}};
  ModelFolder(opt.out_dir).write_metrics(metrics);
  const std::string scores = final_metrics.empty() ? std::string("no test views to score (the split left none)")
                                                   : "test PSNR " + fixed(metrics["mean_psnr"].get<double>(), 2) +
                                                         " dB, SSIM " + fixed(metrics["mean_ssim"].get<double>(), 4);
  std::printf("done: %lld steps in %s, %zu static + %zu distractor Gaussians; %s\n", (long long)trainer.current_step(),
              format_duration(record.wall_seconds, DurationStyle::compact).c_str(), trainer.gaussians().size(),
              trainer.distractor_count(), scores.c_str());
  if (!masks.views.empty())
    std::printf(
        "distractor masks: mean IoU %.3f over %d occluded training views; %.2f%% false positives on %d clean views\n",
        masks.mean_iou, masks.occluded_views, 100 * masks.mean_clean_view_false_positive, masks.clean_views);
  const ReportResult report = write_report(opt.out_dir);
  if (!report.note.empty()) std::printf("report: %s\n", report.note.c_str());
  std::printf(
      "outputs in %s: report.html (open it in a browser), metrics.json, renders/test/%s, point_cloud.ply, "
      "checkpoint.ckpt\n",
      fs::absolute(opt.out_dir).c_str(), config.distractors.enabled ? ", renders/train/" : "");
}

}  // namespace desplat
