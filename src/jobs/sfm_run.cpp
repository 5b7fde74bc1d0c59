// Structure from motion as a job (see include/desplat/jobs/sfm_run.hpp).
#include "desplat/jobs/sfm_run.hpp"

#include <unistd.h>

#include <cstdio>
#include <exception>

#include "jobs/text_format.hpp"

namespace desplat {

using json = nlohmann::json;

int run_sfm_job(sfm::SfmOptions options, bool quiet) {
  const bool tty = ::isatty(STDOUT_FILENO) != 0;
  if (!quiet) options.on_progress = sfm::terminal_progress(stdout, tty);
  const char* newline = tty && !quiet ? "\n" : "";  // end a progress line left mid-way
  try {
    std::printf("%s", sfm_summary_text(sfm::run_sfm(options)).c_str());
  } catch (const sfm::SfmError& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "%sdesplat_sfm: error: %s\n", newline, e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "%sdesplat_sfm: unexpected error: %s\n", newline, e.what());
    return 1;
  }
  return 0;
}

std::string sfm_summary_text(const sfm::SfmResult& r) {
  char line[512];
  std::snprintf(line, sizeof line,
                "registered %d of %d photos, %d points; %s (features %s, %s matching %s, mapping %s)\n",
                r.num_registered, r.num_photos, r.num_points, format_duration(r.seconds).c_str(),
                format_duration(r.extract_seconds).c_str(), sfm::matcher_name(r.matcher),
                format_duration(r.match_seconds).c_str(), format_duration(r.map_seconds).c_str());
  std::string text = line + sfm::describe_attempts(r);
  std::snprintf(line, sizeof line, "mean track length %.2f images, mean reprojection error %.2f px\n",
                r.mean_track_length, r.mean_reprojection_error);
  text += line;
  text += "model:  " + r.sparse_dir.string() + "\n";
  text += "images: " + r.images_dir.string() + "\n";
  text += "log:    " + r.log.string() + "\n";
  text += sfm::describe_lost_photos(r);
  if (r.num_models > 1)
    text += "note: colmap split the photos into " + std::to_string(r.num_models) + " models; the largest is sparse/0\n";
  return text;
}

SfmForTraining run_sfm_for_training(const std::filesystem::path& images, const std::filesystem::path& out) {
  sfm::SfmOptions options;
  options.images = images;
  options.out = out;
  options.overwrite = true;
  options.on_progress = sfm::terminal_progress(stdout, isatty(fileno(stdout)));
  const sfm::SfmResult r = sfm::run_sfm(options);
  std::printf("%s", sfm_training_summary_text(r).c_str());
  return {out, sfm_json(r)};
}

std::string sfm_training_summary_text(const sfm::SfmResult& r) {
  char line[512];
  std::snprintf(line, sizeof line,
                "SfM: %d of %d photos registered, %d points, mean track length %.2f, mean reprojection error %.2f px "
                "(%.0f s)\n",
                r.num_registered, r.num_photos, r.num_points, r.mean_track_length, r.mean_reprojection_error,
                r.seconds);
  return line + sfm::describe_attempts(r) + sfm::describe_lost_photos(r);
}

json sfm_json(const sfm::SfmResult& r) {
  json skipped = json::array(), unregistered = json::array(), attempts = json::array();
  for (const sfm::SfmAttempt& a : r.attempts)
    attempts.push_back({{"step", a.step},
                        {"settings", a.settings},
                        {"registered", a.registered},
                        {"points", a.points},
                        {"seconds", a.seconds}});
  for (const sfm::SkippedFile& f : r.skipped)
    skipped.push_back({{"file", f.path.generic_string()}, {"reason", f.reason}});
  for (const sfm::SkippedFile& f : r.unregistered)
    unregistered.push_back({{"photo", f.path.generic_string()}, {"reason", f.reason}});
  const sfm::CaptureEvidence& e = r.capture;
  const json capture = {{"read", e.read},
                        {"verified_pairs", e.verified_pairs},
                        {"median_partners", e.median_partners},
                        {"max_inliers", e.max_inliers},
                        {"poorly_matched_photos", e.poorly_matched_photos},
                        {"strong_pairs", e.strong_pairs},
                        {"forward_pairs", e.forward_pairs},
                        {"default_start_pairs", e.default_start_pairs},
                        {"median_forward_angle_deg", e.median_forward_angle_deg},
                        {"median_neighbour_tri_angle_deg", e.median_neighbour_tri_angle_deg},
                        {"sequential_photos", e.sequential_photos},
                        {"forward", e.forward},
                        {"summary", e.summary}};
  return {{"photos", r.num_photos},
          {"registered", r.num_registered},
          {"points", r.num_points},
          {"mean_track_length", r.mean_track_length},
          {"mean_reprojection_error_px", r.mean_reprojection_error},
          {"models", r.num_models},
          {"seconds", r.seconds},
          {"cameras", r.cameras.reason},
          {"matching", r.matcher_reason},
          {"stage_seconds",
           {{"extract", r.extract_seconds},
            {"match", r.match_seconds},
            {"evidence", r.evidence_seconds},
            {"map", r.map_seconds}}},
          {"capture", capture},
          {"mapper", r.mapper_reason},
          {"attempts", attempts},
          {"escalation_stopped", r.escalation_stopped},
          {"warning", r.warning},
          {"skipped_files", skipped},
          {"unregistered_photos", unregistered}};
}

}  // namespace desplat
