// Structure from motion as a job: desplat_sfm's whole run, and the step desplat_train --images
// takes before training. Both print to stdout what a person reads (progress, then a summary of
// the photos placed, each step tried and every photo or file left out); run_sfm
// (desplat/sfm/sfm.hpp) does the work.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "desplat/sfm/sfm.hpp"

namespace desplat {

// desplat_sfm: runs `options` with terminal progress on stdout (none when `quiet`), then prints
// sfm_summary_text. Returns the exit status: 0, or 1 after one line on stderr,
// "desplat_sfm: error: …" (an SfmError) or "desplat_sfm: unexpected error: …".
int run_sfm_job(sfm::SfmOptions options, bool quiet);

// What desplat_sfm prints after a run: photos placed and the time of each stage, the attempts,
// track length and reprojection error, where the model, images and log are, the photos left
// out and, when colmap split the photos, how many models it made.
std::string sfm_summary_text(const sfm::SfmResult& result);

// desplat_train --images: SfM of `images` into `out` (an earlier run there is replaced), with
// terminal progress and sfm_training_summary_text on stdout. SfmError when it fails.
struct SfmForTraining {
  std::filesystem::path data_dir;  // `out`: images/ and sparse/0/, what the scene loader reads
  nlohmann::json metrics;          // sfm_json of the result, metrics.json's "sfm"
};
SfmForTraining run_sfm_for_training(const std::filesystem::path& images, const std::filesystem::path& out);

// The shorter summary desplat_train prints before it trains: one line of counts and time, the
// attempts and the photos left out.
std::string sfm_training_summary_text(const sfm::SfmResult& result);

// What SfM made of the photos, as metrics.json records it (report.html's "Structure from
// motion"): counts, track length, reprojection error [px], seconds, the camera and matcher
// choices, every attempt, the warning, and each skipped file and unplaced photo with its reason.
nlohmann::json sfm_json(const sfm::SfmResult& result);

}  // namespace desplat
