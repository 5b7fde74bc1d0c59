// A trained model's folder (desplat_train --out), as one type: every command that writes or
// opens a model goes through ModelFolder, so the files and their meaning live in one place.
//
//   config.json      {"train": the effective TrainConfig, "scene": the SceneRecipe,
//                     "run": how the run was invoked (static_only, …)}
//   checkpoint.ckpt  the full training state (train/training_checkpoint.hpp), written atomically
//   metrics.json     the evaluation (jobs/training_run.hpp lists its fields)
//
// The recipe records everything needed to load the same views again: the data folder, the
// downscale, the split rule with every parameter as given, and the split's outcome (the
// training and test image names). A model reopens its views from the recorded names, so it
// still opens after a list or .tsv file has moved; the rule and its parameters stay for the
// record and for --resume's check that nothing changed.
//
// Ownership and threads: ModelFolder holds only the folder's path; reads and writes are
// independent calls. Errors throw std::invalid_argument naming the file and the problem.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/io/checkpoint.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/io/splits.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

struct SceneRecipe {
  std::filesystem::path data_dir;  // absolute: images/ + sparse/0/
  int downscale = 1;
  SplitOptions split;                                // as given to training (list and .tsv paths absolute)
  std::vector<std::string> train_views, test_views;  // the split's outcome, in scene order
  std::filesystem::path masks_dir;                   // absolute: the user's masks in use; empty: none

  // The recipe of a loaded scene: its options plus the views the split gave.
  static SceneRecipe of(const Scene& scene, const std::filesystem::path& data_dir, const SceneOptions& options);
  // Options that load exactly train_views and test_views from data_dir at this downscale.
  SceneOptions reopen_options() const;
  // "" when `other` loads the same views at the same size from the same folder, else what differs.
  std::string difference(const SceneRecipe& other) const;

  nlohmann::json to_json() const;
  static SceneRecipe from_json(const nlohmann::json& j);  // throws std::invalid_argument
};

class ModelFolder {
 public:
  explicit ModelFolder(std::filesystem::path dir) : dir_(std::move(dir)) {}

  const std::filesystem::path& dir() const { return dir_; }
  std::filesystem::path config_path() const { return dir_ / "config.json"; }
  std::filesystem::path checkpoint_path() const { return dir_ / "checkpoint.ckpt"; }
  std::filesystem::path metrics_path() const { return dir_ / "metrics.json"; }

  struct Config {
    TrainConfig train;
    SceneRecipe scene;
    nlohmann::json run = nlohmann::json::object();
    // Settings the file's "train" lacks (written by a build before they existed); `train`
    // holds today's defaults for them.
    std::vector<std::string> unrecorded_settings;
  };
  void write_config(const Config& config) const;  // atomically
  // Throws when the file is missing, not JSON, or lacks the recipe. A config.json from before
  // the recipe was recorded ("run" with split_rule / split_every_nth) still opens for the two
  // rules that need no files (every-nth, all-train) and is refused for the others.
  Config read_config() const;
  // config.json as written (for showing it, e.g. in report.html); throws like read_config.
  nlohmann::json read_config_json() const;

  bool has_checkpoint() const { return std::filesystem::exists(checkpoint_path()); }
  void write_checkpoint(const Trainer& trainer, const nlohmann::json& extra_metadata) const;  // atomically
  Checkpoint read_checkpoint() const;
  // The outputs of a training run (config.json, checkpoint.ckpt, metrics.json,
  // point_cloud.ply, renders/, report.html) that exist in the folder: a fresh run refuses a folder that
  // holds any of them unless told to replace them (remove_training_outputs removes exactly
  // these; other files are left alone).
  std::vector<std::filesystem::path> existing_training_outputs() const;
  void remove_training_outputs() const;

  void write_metrics(const nlohmann::json& metrics) const;  // atomically
  nlohmann::json read_metrics() const;

 private:
  std::filesystem::path dir_;
};

}  // namespace desplat
