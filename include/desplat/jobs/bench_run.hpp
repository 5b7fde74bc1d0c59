// desplat_bench: what accuracy costs in time. Trains a grid of settings on one or more scenes
// and records test PSNR/SSIM (and distractor-mask IoU where the scene has ground truth)
// against training wall time, then plots them.
//
// Grid file (JSON; unknown keys are errors naming the file):
//   {
//     "scenes": ["out/bench", "out/bench_clutter_040"],  // relative to the grid file's folder
//     "steps": 7000,          // per run unless the run's preset or config sets "iterations"
//     "eval_every": 500,      // a point on every curve each N steps (and at the end)
//     "threads": 0,           // OpenMP threads, 0 = all cores
//     "score_at": "full",     // test views at "full" resolution or at each run's "training" one
//     "runs": [               // one curve per run and scene
//       {"name": "DeSplat", "config": {}},
//       {"name": "static-only", "config": {"distractors": {"enabled": false}}},
//       {"name": "DeSplat, 1/2 res", "downscale": 2, "config": {"sh_degree": 1}},
//       {"name": "fast", "preset": "fast"}  // train/presets.hpp; its length is the preset's
//     ]
//   }
// "config" holds TrainConfig overrides in config.json's format (train_config_json.hpp), applied
// on top of the run's "preset" (default: "default"), as desplat_train --preset --config does.
// A run with a preset trains for the preset's iterations unless its config sets them.
// With "score_at": "full" (the default) test views are scored at full resolution whatever a
// run's training downscale, so runs at different resolutions are comparable; "training"
// scores them at the run's own resolution (for comparing settings at one low resolution,
// where upsampling blur would hide the differences). Masks are scored at the training resolution.
// Wall time counts training steps only, not evaluation.
//
// Outputs in the output folder: bench.csv (rewritten atomically after every point, so an
// interrupted benchmark keeps what it measured; resume skips finished runs),
// <scene>_psnr_vs_time.png, <scene>_ssim_vs_time.png, <scene>_iou_vs_time.png (scenes with
// masks, DeSplat runs), and psnr_vs_clutter.png when two or more scenes carry a clutter ratio
// (scene.json from desplat_synth): final test PSNR per run against the scene's clutter ratio;
// with a static-only run on a clutter-free scene also clutter_summary.csv,
// recovered_vs_clutter.png and iou_vs_clutter.png (jobs/clutter_summary.hpp).
// The plots are drawn by gnuplot (eval/plot.hpp); desplat_bench also writes report.html
// (jobs/report.hpp: write_bench_report).
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "desplat/train/trainer.hpp"

namespace desplat {

struct BenchRun {
  std::string name;
  nlohmann::json config = nlohmann::json::object();  // TrainConfig overrides
  std::string preset;                                // train/presets.hpp; empty: "default", grid's steps
  int downscale = 1;
};

struct BenchGrid {
  std::vector<std::filesystem::path> scenes;
  std::vector<BenchRun> runs;
  int64_t steps = 7000;
  int eval_every = 500;
  int threads = 0;
  bool score_at_full_resolution = true;
};

// Throws std::invalid_argument naming the file for unreadable or invalid grids (bad JSON,
// unknown keys, no scenes or runs, duplicate run names, a config TrainConfig rejects).
BenchGrid read_bench_grid(const std::filesystem::path& file);

// The training settings of one run: its preset, its config on top, the grid's steps (unless
// the run has a preset or sets "iterations") and threads. Throws std::invalid_argument for an
// unknown preset or a config TrainConfig rejects.
TrainConfig bench_run_config(const BenchGrid& grid, const BenchRun& run);

struct BenchPoint {
  std::string scene, run;
  double clutter_ratio = -1;  // from the scene's scene.json; -1 when unknown
  bool desplat = true;        // the run trains distractors
  int64_t step = 0;
  double train_seconds = 0;   // cumulative, training steps only
  double psnr = 0, ssim = 0;  // mean over the scene's test views, full resolution
  double mask_iou = -1;       // mean over occluded training views; -1 when the scene has none
  size_t static_gaussians = 0, distractor_gaussians = 0;
};

void write_bench_csv(const std::filesystem::path& path, const std::vector<BenchPoint>& points);
// Throws std::invalid_argument naming the file and line for a malformed CSV.
std::vector<BenchPoint> read_bench_csv(const std::filesystem::path& path);

// Runs every (scene, run) pair in order, appending points and rewriting out_dir/bench.csv after
// each. With resume, points of runs already finished in an existing bench.csv are kept and
// those runs skipped (an unfinished run starts over). Stops early (returning what it has) when
// stop_requested becomes true. `report` gets each point as it is measured (may be empty).
std::vector<BenchPoint> run_bench(const BenchGrid& grid, const std::filesystem::path& out_dir, bool resume,
                                  const std::atomic<bool>& stop_requested,
                                  const std::function<void(const BenchPoint&)>& report);

// Writes the plots described above; returns the files written.
std::vector<std::filesystem::path> write_bench_plots(const std::filesystem::path& out_dir,
                                                     const std::vector<BenchPoint>& points);

}  // namespace desplat
