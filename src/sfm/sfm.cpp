// Structure from motion by running the colmap executable; see include/desplat/sfm/sfm.hpp.
// run_sfm puts the pieces of src/sfm/pipeline.hpp together.
#include "desplat/sfm/sfm.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "desplat/core/stopwatch.hpp"
#include "desplat/io/colmap.hpp"
#include "sfm/pipeline.hpp"
#include "sfm/quoting.hpp"

namespace desplat::sfm {
namespace fs = std::filesystem;
using namespace pipeline;

namespace {

void check_photos_found(const PhotoScan& scan, const fs::path& dir) {
  if (!scan.photos.empty()) return;
  if (scan.skipped.empty())
    fail(SfmErrorKind::BadImages,
         "the images folder " + in_quotes(dir) + " is empty; put your photos (JPEG, PNG or TIFF) in it");
  const SkippedFile& first = scan.skipped.front();
  fail(SfmErrorKind::BadImages, "no readable photos in " + in_quotes(dir) + ": none of its " +
                                    std::to_string(scan.skipped.size()) + " file(s) is a usable photo (e.g. " +
                                    in_quotes(first.path) + ": " + first.reason + ")");
}

int resolve_min_registered(const SfmOptions& o, int num_photos) {
  const double share = o.min_registered_share;
  if (!(share > 0 && share <= 1))
    fail(SfmErrorKind::BadOptions, "--min-registered-share must be in (0, 1], got " + std::to_string(share));
  const int wanted = required_registered(share, num_photos);
  if (num_photos < wanted)
    fail(SfmErrorKind::BadImages, "found only " + std::to_string(num_photos) + " photo(s) in " + in_quotes(o.images) +
                                      "; structure from motion needs at least " + std::to_string(wanted) +
                                      " overlapping photos (20-200 is typical)");
  return wanted;
}

// ---- Options -----------------------------------------------------------------------------

void check_camera_model(const std::string& name) {
  if (colmap::camera_model_from_name(name)) return;
  std::string names;
  for (const auto& m : colmap::camera_models()) names += std::string(names.empty() ? "" : ", ") + m.name;
  fail(SfmErrorKind::BadOptions, "unknown camera model '" + name + "'; use one of " + names);
}

fs::path require_colmap(const std::string& name) {
  if (auto path = find_executable(name)) return *path;
  if (name.find('/') != std::string::npos)
    fail(SfmErrorKind::ColmapMissing,
         "the colmap executable " + in_quotes(name) + " does not exist or is not executable");
  fail(SfmErrorKind::ColmapMissing, "'" + name +
                                        "' was not found on PATH; install it with scripts/install_deps.sh or "
                                        "apt-get install colmap (or pass its path with --colmap)");
}

// The matcher and why, for the log. Only a large capture with --matcher auto reads its photos
// to judge their order: below kExhaustiveMaxImages every pair is matched whatever the order.
std::pair<Matcher, std::string> resolve_matcher(const SfmOptions& o, const std::vector<fs::path>& photos) {
  const int n = static_cast<int>(photos.size());
  if (o.matcher != Matcher::Auto)
    return {o.matcher, std::string(matcher_name(o.matcher)) + ", as asked (--matcher " + matcher_name(o.matcher) + ")"};
  if (n <= kExhaustiveMaxImages)
    return {Matcher::Exhaustive, "exhaustive: " + std::to_string(n) + " photos are few enough to match every pair"};
  const CaptureOrder order = detect_capture_order(o.images, photos);
  const Matcher m = choose_matcher(Matcher::Auto, n, order.ordered);
  return {m, std::string(matcher_name(m)) + ": " + std::to_string(n) + " photos, " + order.reason +
                 (m == Matcher::Exhaustive ? "; every pair is matched, which takes time growing with the square "
                                             "of the number of photos"
                                           : "; each photo is matched with its neighbours in name order")};
}

}  // namespace

// ---- Public ------------------------------------------------------------------------------

std::optional<Matcher> matcher_from_name(const std::string& name) {
  for (Matcher m : {Matcher::Auto, Matcher::Exhaustive, Matcher::Sequential, Matcher::Spatial})
    if (name == matcher_name(m)) return m;
  return std::nullopt;
}

const char* matcher_name(Matcher matcher) {
  switch (matcher) {
    case Matcher::Auto:
      return "auto";
    case Matcher::Exhaustive:
      return "exhaustive";
    case Matcher::Sequential:
      return "sequential";
    case Matcher::Spatial:
      return "spatial";
  }
  return "?";
}

Matcher choose_matcher(Matcher requested, int num_images, bool photos_in_order) {
  if (requested != Matcher::Auto) return requested;
  return num_images > kExhaustiveMaxImages && photos_in_order ? Matcher::Sequential : Matcher::Exhaustive;
}

int required_registered(double share, int num_images) {
  return std::max(3, static_cast<int>(std::ceil(share * num_images - 1e-9)));
}

double default_stage_time_limit(SfmStage stage, Matcher matcher, int num_photos) {
  const double n = std::max(1, num_photos);
  switch (stage) {
    case SfmStage::Extract:
      return 300 + 30 * n;
    case SfmStage::Match:
      return matcher == Matcher::Exhaustive ? 600 + 3 * n * (n - 1) / 2 : 600 + 60 * n;
    case SfmStage::Map:
      return 600 + 60 * n;
  }
  return 0;
}

std::string describe_lost_photos(const SfmResult& r, size_t max_names) {
  std::string text;
  if (!r.skipped.empty()) {
    text += std::to_string(r.skipped.size()) + " file(s) in the images folder were not used:\n";
    for (size_t i = 0; i < r.skipped.size() && i < max_names; ++i)
      text += "  " + r.skipped[i].path.generic_string() + ": " + r.skipped[i].reason + "\n";
    if (r.skipped.size() > max_names) text += "  ... and " + std::to_string(r.skipped.size() - max_names) + " more\n";
  }
  if (!r.unregistered.empty()) {
    text += std::to_string(r.unregistered.size()) + " of " + std::to_string(r.num_photos) +
            " photos could not be placed by structure from motion (not in the model, so not trained on):\n";
    for (size_t i = 0; i < r.unregistered.size() && i < max_names; ++i)
      text += "  " + r.unregistered[i].path.generic_string() + ": " + r.unregistered[i].reason + "\n";
    if (r.unregistered.size() > max_names)
      text += "  ... and " + std::to_string(r.unregistered.size() - max_names) + " more\n";
  }
  return text;
}

std::string describe_attempts(const SfmResult& r) {
  std::string text = "cameras: " + r.cameras.reason + "\nmatching: " + r.matcher_reason + "\n";
  if (!r.capture.summary.empty()) text += "capture: " + r.capture.summary + "\n";
  if (!r.mapper_reason.empty()) text += "mapper: " + r.mapper_reason + "\n";
  for (const SfmAttempt& a : r.attempts) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-18s %d of %d photos, %d points, %.0f s", (a.step + ":").c_str(), a.registered,
                  r.num_photos, a.points, a.seconds);
    text += line + std::string(" (") + a.settings + ")\n";
  }
  if (!r.escalation_stopped.empty()) text += "escalation stopped: " + r.escalation_stopped + "\n";
  if (!r.warning.empty()) text += "warning: " + r.warning + "\n";
  return text;
}

SfmResult run_sfm(const SfmOptions& o) {
  const Stopwatch clock;
  if (!o.camera_model.empty()) check_camera_model(o.camera_model);
  if (o.stage_time_limit_s && !(*o.stage_time_limit_s > 0))
    fail(SfmErrorKind::BadOptions,
         "the stage time limit must be positive, got " + std::to_string(*o.stage_time_limit_s) + " s");
  const fs::path colmap_exe = require_colmap(o.colmap);
  const PhotoScan scan = scan_photos(o.images);
  check_photos_found(scan, o.images);
  const int num_photos = static_cast<int>(scan.photos.size());
  const int min_registered = resolve_min_registered(o, num_photos);
  const CameraChoice cameras = choose_cameras(o.cameras, scan.cameras);

  const auto [matcher, matcher_reason] = resolve_matcher(o, scan.photos);
  Context c{colmap_exe, Layout(o.out), {}, o.on_progress, num_photos, matcher, o.stage_time_limit_s};
  prepare_output(o, c.layout, scan.photos);
  c.log.open(c.layout.log, std::ios::binary | std::ios::trunc);
  if (!c.log) fail(SfmErrorKind::OutputExists, "cannot write the log file " + in_quotes(c.layout.log));
  c.log << "######## desplat_sfm: " << num_photos << " photos; " << cameras.reason
        << "\n######## matching: " << matcher_reason << "\n"
        << std::flush;

  Ladder ladder{c, o, min_registered, cameras.single, scan.photos};
  const std::string model = o.camera_model.empty() ? auto_camera_model(cameras.single) : o.camera_model;
  ladder.first_run((cameras.single ? "one shared camera, " : "one camera per photo, ") + model);
  if (o.escalate) ladder.run();
  if (ladder.best.registered() == 0) no_model(c, matcher, ladder.last_map);
  Candidate best = install_winner(c, ladder.best);
  renumber_models(best.models, c.layout.sparse_root);
  check_registered(c, best.models, c.layout.database, min_registered, scan.photos, ladder.attempts, ladder.stopped);

  SfmResult r;
  r.images_dir = c.layout.images;
  r.sparse_dir = best.models[0].dir;
  r.database = c.layout.database;
  r.log = c.layout.log;
  r.matcher = matcher;
  r.matcher_reason = matcher_reason;
  r.cameras = cameras;
  r.attempts = ladder.attempts;
  r.num_photos = num_photos;
  r.num_registered = best.models[0].registered;
  r.num_points = best.models[0].points;
  r.num_models = static_cast<int>(best.models.size());
  r.skipped = scan.skipped;
  r.unregistered = photos_not_in(best.models, scan.photos, c.layout.database);
  r.mean_track_length = best.models[0].mean_track_length;
  r.mean_reprojection_error = best.models[0].mean_reprojection_error;
  if (r.num_registered < kEscalateBelowShare * num_photos)
    r.warning = std::to_string(num_photos - r.num_registered) + " of " + std::to_string(num_photos) +
                " photos could not be placed" + (o.escalate ? " even after escalation" : "") +
                "; they are not trained on (see the list below)";
  r.seconds = clock.seconds();
  r.extract_seconds = ladder.extract_seconds, r.match_seconds = ladder.match_seconds;
  r.map_seconds = ladder.map_seconds;
  r.evidence_seconds = ladder.evidence_seconds;
  r.capture = ladder.capture;
  r.mapper_reason = ladder.mapper_reason;
  r.escalation_stopped = ladder.stopped;
  return r;
}

}  // namespace desplat::sfm
