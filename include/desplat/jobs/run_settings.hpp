// One home for a training run's settings: presets, --config (a file, inline JSON, or a run's
// own config.json), the command-line flags, --effects (auto and its transient probe) and
// --resume's reconciliation with the recorded model become one TrainConfig plus the run
// record config.json keeps. The order, each step overriding the ones before:
//
//   1. --preset (presets.hpp; unset: "default")
//   2. --config (TrainConfig's settings table, docs/CONFIG.md)
//   3. --iterations, --seed, --threads, --static-only, an explicit --effects list, and the
//      ablation switches (--distractors-per-view, --no-distractor-density, --no-regularization)
//   4. --effects auto (the default): appearance and background from the SfM tracks' evidence,
//      distractors from the transient probe (docs/METHOD.md §10); on --resume, the effects
//      the model was trained with
//   5. --resume: the recorded settings, with only iterations, threads and kernel_isa taken
//      from 1–3 (any other difference is refused)
//
// Steps 1–3 need no scene (request_settings: every error there comes before any file is
// read or written); 4–5 need the training data (resolve_settings).
#pragma once

#include <atomic>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "desplat/comm/communicator.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/train/train_config.hpp"
#include "desplat/train/training_data.hpp"

namespace desplat {

// Steps 1–3.
struct RequestedSettings {
  TrainConfig config;
  nlohmann::json overrides = nlohmann::json::object();  // the --config settings as given
  std::string preset;                                   // as named, or "default"
  bool auto_effects = false;                            // --effects auto: step 4 decides the effects
};
// Throws std::invalid_argument naming the option or setting, what is wrong and what to do.
RequestedSettings request_settings(const TrainingRunOptions& options);

// --config's text: a file's path, or the JSON itself when it starts with '{'. The JSON must be
// an object: the settings, or a whole config.json desplat_train wrote (its "train" part is the
// settings; its "scene" and "run" records describe that run's data and effects, which this
// run takes from --data, the split options and --effects, so they are ignored and a note says
// so on stdout).
nlohmann::json read_config_option(const std::string& config);

// Steps 4–5: the settings the Trainer is built with and config.json's "run" record.
struct ResolvedSettings {
  TrainConfig config;
  nlohmann::json run;               // static_only, preset, effects, effects_chosen_by, effects_evidence
  std::string effects_chosen_by;    // "auto" or "the command line and preset"
  nlohmann::json effects_evidence;  // auto's evidence (null when the effects were given)
};
// With `comm` of several ranks it is a collective (auto's evidence and probe), every rank
// resolving the same settings. `resumed` is the model's config.json on --resume (else null). Returns nullopt when
// `stop_requested` interrupted the transient probe (nothing was written).
std::optional<ResolvedSettings> resolve_settings(const RequestedSettings& requested, const TrainingRunOptions& options,
                                                 const TrainingData& data, const ModelFolder::Config* resumed,
                                                 const std::string& record_name,
                                                 const std::atomic<bool>& stop_requested, Communicator* comm = nullptr);

}  // namespace desplat
