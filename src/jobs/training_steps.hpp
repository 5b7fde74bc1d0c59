// The steps of run_training (training_run.cpp), each in its own file: load the inputs
// (training_inputs.cpp), train (training_loop.cpp), evaluate and write (training_outputs.cpp).
// Private to the jobs layer.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/io/scene.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/jobs/run_settings.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

// What a run trains on, checked before anything is written to the output folder (SfM on
// --images aside, which writes only <out>/sfm).
struct RunInputs {
  std::filesystem::path data_dir;  // --data, or SfM's model of --images
  nlohmann::json sfm_summary;      // null unless this run ran SfM
  Scene scene;
  SceneRecipe recipe;
  std::optional<ModelFolder::Config> resumed;  // --resume: the model's config.json
  TrainingData data;
};
// Runs SfM on --images, loads the scene (on --resume at the downscale config.json records
// unless --downscale is given), and on --resume reads config.json and checks the scene is
// the one the model was trained on. Throws std::invalid_argument / SceneError.
// As rank `rank` of `ranks`: only this rank's photos (load_training_data).
RunInputs load_run_inputs(const TrainingRunOptions& options, int rank = 0, int ranks = 1);

// What the training loop recorded: metrics.json's history and the per-step timings at full
// resolution (each vector one entry per such step).
struct TrainingRecord {
  nlohmann::json history = nlohmann::json::array();
  std::vector<double> forward, backward, loss, optimizer, distractor, appearance, background, total, distractor_share;
  std::vector<double> pairs, ns_forward, ns_forward_backward, visible_share;
  // Every step: this rank's collectives (bytes, seconds; zero in one process) and the step's time.
  std::vector<double> comm_bytes, comm_seconds, step_seconds;
  double wall_seconds = 0;                                // this process's training, without the final evaluation
  nlohmann::json eta_accuracy = nlohmann::json::array();  // TrainingEta::accuracy
  double eta_timing_seconds = 0;                          // TrainingEta::timing_seconds
  bool interrupted = false;                               // stopped by stop_requested (checkpoint written)
};
// Trains `trainer` to config.iterations with progress output, periodic evaluation and
// checkpoints (`save` writes one).
TrainingRecord train_to_end(Trainer& trainer, const TrainingRunOptions& options, const Scene& scene,
                            const std::function<void()>& save, const std::atomic<bool>& stop_requested);

// The final evaluation and every output but config.json and the checkpoint: renders/,
// point_cloud.ply, metrics.json and report.html, with the closing lines on stdout.
void write_training_outputs(const Trainer& trainer, const TrainingRunOptions& options, const RunInputs& inputs,
                            const ResolvedSettings& settings, const TrainingRecord& record);

// Test-view PSNR/SSIM per image and their means (null means without test views).
nlohmann::json metrics_json(const std::vector<ViewMetrics>& metrics);

}  // namespace desplat
