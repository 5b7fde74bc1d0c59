// The whole training job behind desplat_train: load the scene (or run SfM first),
// train with progress output, evaluate, checkpoint, and write the outputs.
//
// Output folder (`out_dir`):
//   config.json          effective training configuration + run options
//   checkpoint.ckpt      latest checkpoint (atomic; --resume continues from it)
//   metrics.json         test-view PSNR/SSIM per image and mean, evaluation history,
//                        Gaussian counts and MB (static, distractor), timings (median per
//                        step at full resolution, distractor branch separately), and
//                        distractor_masks (IoU per training view and mean) when the scene
//                        has ground-truth masks (masks.hpp)
//   renders/test/*.png   ground truth | render, side by side, per test view
//   renders/train/*.png  DeSplat only: truth | static | distractor | composite | mask per
//                        training view (the paper's Fig. 2)
//   point_cloud.ply      static Gaussians as a standard 3DGS PLY, original COLMAP frame
#pragma once

#include <atomic>
#include <filesystem>
#include <optional>
#include <string>

#include "desplat/comm/communicator.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/train/training_data.hpp"

namespace desplat {

struct TrainingRunOptions {
  std::filesystem::path data_dir;    // images/ + sparse/0/
  std::filesystem::path images_dir;  // instead of data_dir: run SfM on a folder of photos
  std::filesystem::path out_dir;
  // presets.hpp; the config file applies on top of it. Unset: "default" (on --resume: the
  // settings the model was trained with).
  std::optional<std::string> preset;
  // JSON overrides of TrainConfig (docs/CONFIG.md): a file's path, or the JSON text itself when
  // it starts with '{' (desplat_train --config '{"num_downscales": 0}'); a run's whole
  // config.json is accepted (its "train" part applies; jobs/run_settings.hpp).
  std::string config;
  std::optional<int64_t> iterations;
  std::optional<uint64_t> seed;
  std::optional<int> threads;
  std::optional<int> batch;  // TrainConfig::batch: training views per optimizer step
  bool static_only = false;  // the Splatfacto baseline: no distractors (= effects "none")
  // train/effects.hpp: auto, none or a list; unset: auto (none with static_only, the preset's
  // own set with --preset paper).
  std::optional<std::string> effects;
  // Ablation switches (override the config file): distractors.initial_count with
  // reference_pixels = 0 (exactly that many per view), distractors.density_control = false,
  // distractors.regularize = false.
  std::optional<int> distractors_per_view;
  bool no_distractor_density = false;
  bool no_regularization = false;
  // Continue out_dir's checkpoint with the settings its config.json records. Only the length
  // of the run (iterations) and threads and kernel_isa (float rounding at most) may change;
  // any other setting given here must agree with the record, or the resume is refused.
  bool resume = false;
  // A fresh run into a folder that holds an earlier run's outputs is refused (it would
  // overwrite that model's checkpoint and leave its renders mixed with the new ones) unless
  // `overwrite`, which removes those outputs first.
  bool overwrite = false;
  // Train on images downscaled by this factor. Unset: 1, or on --resume the factor config.json
  // records.
  std::optional<int> downscale;
  SplitOptions split;
  std::filesystem::path masks_dir;  // the user's masks (masks.hpp); empty: <data>/masks if present
  int eval_every = 0;               // 0: only at the end
  int checkpoint_every = 1000;
  int log_every = 100;  // plain-log interval when stdout is not a terminal
};

// Returns the process exit code: 0 done, 130 interrupted (checkpoint written, or nothing
// written when interrupted before training started). Throws for bad input (messages name the
// file or setting, the problem and what to do); every check of the settings and the inputs
// runs before anything is written to out_dir (SfM on images_dir aside, which writes
// out_dir/sfm), so a refused run leaves no outputs that would block the next one.
// With `comm` of several ranks (mpirun or srun; docs/METHOD.md §6, ranks) this is one rank of a
// data-parallel job: every rank calls it alike; each loads only its own views' photos, rank 0
// alone writes out_dir, and an error on any rank ends the job (the caller aborts it).
int run_training(const TrainingRunOptions& options, const std::atomic<bool>& stop_requested,
                 Communicator* comm = nullptr);

// Loads a scene and its pixels into TrainingData (normalized frame). As rank `rank` of
// `ranks` only the photos and masks of that rank's views (rank_of_view) are read.
TrainingData load_training_data(const Scene& scene, int rank = 0, int ranks = 1);
// Scene view i's photo in 8 bits and its mask (empty without one), as load_training_data holds
// them (masked pixels zeroed). Returns whether the file held values 8 bits round.
bool load_view_photo(const Scene& scene, size_t i, ByteImage& photo, std::vector<uint8_t>& keep);

}  // namespace desplat
