// The escalation steps of a structure-from-motion run (see src/sfm/pipeline.hpp): the first run
// with the mapper thresholds the capture evidence chooses (colmap's defaults, or the forward-walk
// thresholds), then relaxed mapper thresholds, registering the photos left out, guided matching
// and more features, each only while too few photos are placed, and the two that match again
// only while some photo left out lacks verified matches.
#include <algorithm>
#include <cstdio>
#include <map>
#include <set>
#include <system_error>

#include "desplat/core/stopwatch.hpp"
#include "sfm/match_evidence.hpp"
#include "sfm/pipeline.hpp"
#include "sfm/quoting.hpp"
#include "sfm/two_view_evidence.hpp"

namespace desplat::sfm::pipeline {
namespace fs = std::filesystem;

// colmap's defaults are made for thousands of features per photo over wide baselines. A
// capture that registers fewer than kEscalateBelowShare of its photos gets the steps below, in
// order of cost, until one reaches that share; the model with the most photos wins.

namespace {

// colmap starts a model from a pair with 100 inliers and 16° of triangulation angle and adds a
// photo with 30 inliers. Small or low-texture photos, narrow baselines and collections with few
// shared features have no such pair. A third to a half of each still leaves tens of inliers,
// far above the 5 a two-view pose needs, so a wrong start stays unlikely (the reprojection
// error of the result is reported).
const std::vector<std::string> kRelaxedMapper = {"--Mapper.init_min_num_inliers",     "30",
                                                 "--Mapper.init_min_tri_angle",       "4",
                                                 "--Mapper.abs_pose_min_num_inliers", "15"};
// Registering into a finished model uses the same per-photo threshold.
const std::vector<std::string> kRelaxedRegistration = {"--Mapper.abs_pose_min_num_inliers", "15"};
// A forward walk (is_forward_capture, include/desplat/sfm/sfm.hpp) from the first mapper run:
//  - init_max_forward_motion 1.0: every pair of a walk moves along its viewing direction, and
//    colmap's 0.95 refuses any such pair as the model's start;
//  - init_min_tri_angle 2: a forward pair sees the points ahead under angles that shrink towards
//    the direction of travel, a few degrees in the median, far below colmap's 16; 2° still fixes a
//    point's depth to about 6 % at 1 px of error on a 500 px focal length;
//  - tri_min_angle 0.5: colmap's 1.5° drops the points ahead of the camera, exactly the ones the
//    next photo sees; bundle adjustment weighs what is kept by its reprojection error;
//  - abs_pose_min_num_inliers 15: with fewer points per photo, 15 inliers still hold a 6-DoF pose
//    (3 points determine one) five times over under RANSAC;
//  - init_min_num_inliers 50: far above the 5–8 a two-view geometry needs, so a start pair
//    that passes the angle tests is not refused for colmap's 100 alone.
const std::vector<std::string> kForwardMapper = {
    "--Mapper.init_min_tri_angle",   "2",   "--Mapper.init_max_forward_motion",  "1.0",
    "--Mapper.tri_min_angle",        "0.5", "--Mapper.abs_pose_min_num_inliers", "15",
    "--Mapper.init_min_num_inliers", "50"};
// The relaxed step of a forward walk: its thresholds with the relaxed step's 30 start inliers.
const std::vector<std::string> kForwardRelaxedMapper = {
    "--Mapper.init_min_tri_angle",   "2",   "--Mapper.init_max_forward_motion",  "1.0",
    "--Mapper.tri_min_angle",        "0.5", "--Mapper.abs_pose_min_num_inliers", "15",
    "--Mapper.init_min_num_inliers", "30"};
// Registering into a forward walk's model keeps its small-angle points too.
const std::vector<std::string> kForwardRegistration = {"--Mapper.abs_pose_min_num_inliers", "15",
                                                       "--Mapper.tri_min_angle", "0.5"};
// Guided matching re-matches each verified pair along its epipolar geometry, recovering matches
// the ratio test threw away; it costs about one more matching pass.
const std::vector<std::string> kGuidedMatching = {"--SiftMatching.guided_matching", "1"};
// Twice colmap's 8,192 features, and domain-size pooling (descriptors pooled over scales,
// sturdier across zoom and viewpoint; CPU-only in colmap): the most expensive step, as
// matching cost grows with the square of the features.
const std::vector<std::string> kMoreFeatures = {"--SiftExtraction.max_num_features", "16000",
                                                "--SiftExtraction.domain_size_pooling", "1"};

// The escalation steps' names, as the log, metrics.json and the result say them.
constexpr const char* kStepRelaxedMapper = "relaxed mapper";
constexpr const char* kStepRegisterRest = "register the rest";
constexpr const char* kStepGuidedMatching = "guided matching";
constexpr const char* kStepMoreFeatures = "more features";

bool better(const Candidate& a, const Candidate& b) {
  return a.registered() != b.registered() ? a.registered() > b.registered() : a.points() > b.points();
}

// A mapper run into w.sparse_root. A mapper that ends without a model is an empty candidate;
// any other failure is an error.
Candidate run_mapper(Context& c, const SfmOptions& o, const Workspace& w, int min_registered,
                     const std::vector<std::string>& extra, StageOutput* last_map) {
  std::error_code ec;
  fs::create_directories(w.sparse_root, ec);
  const StageOutput map =
      run_stage(c, SfmStage::Map, "mapper", map_args(o, c.layout, w, min_registered, extra), c.num_photos);
  Candidate cand{w, collect_models(w.sparse_root)};
  const bool have_model = !cand.models.empty() && cand.models[0].registered > 0;
  if (map.exit.how == ProcessExit::How::Exited && !cand.models.empty() && cand.models[0].registered < 0)
    fail(SfmErrorKind::NoModel, "colmap mapper wrote a model that cannot be read: " + cand.models[0].error +
                                    ". The full output is in " + in_quotes(c.layout.log));
  if (!have_model && !(map.exit.ok() || said_no_model(map))) stage_failed(c, "mapper", map);
  if (have_model && !map.exit.ok()) stage_failed(c, "mapper", map);
  if (!have_model) cand.models.clear();
  *last_map = map;
  SfmProgress done = map.last;
  done.model = 1, done.done = cand.registered(), done.finished = true;
  report(c, done);
  return cand;
}

// image_registrator places the photos `from` lacks into its largest model (with the relaxed
// per-photo threshold), then bundle_adjuster refines the whole. Photos of colmap's smaller
// sub-models join this way too: model_merger needs photos two models share, which sub-models
// of one mapper run do not have.
Candidate register_rest(Context& c, const SfmOptions& o, const Candidate& from, const fs::path& folder,
                        const std::vector<std::string>& settings) {
  const Workspace w{from.where.database, folder / "sparse"};
  const fs::path model = w.sparse_root / "0";
  std::error_code ec;
  fs::create_directories(model, ec);
  std::vector<std::string> reg = {
      "--database_path", w.database.string(),    "--input_path",         from.models[0].dir.string(), "--output_path",
      model.string(),    "--Mapper.num_threads", threads(o.num_threads), "--log_to_stderr",           "1"};
  reg.insert(reg.end(), settings.begin(), settings.end());
  const StageOutput r = run_stage(c, SfmStage::Map, "image_registrator", std::move(reg), c.num_photos);
  if (!r.exit.ok()) stage_failed(c, "image_registrator", r);
  const StageOutput ba = run_stage(
      c, SfmStage::Map, "bundle_adjuster",
      {"--input_path", model.string(), "--output_path", model.string(), "--log_to_stderr", "1"}, c.num_photos);
  if (!ba.exit.ok()) stage_failed(c, "bundle_adjuster", ba);
  Candidate cand{w, collect_models(w.sparse_root)};
  if (!cand.models.empty() && cand.models[0].registered < 0)
    fail(SfmErrorKind::NoModel, "colmap image_registrator wrote a model that cannot be read: " + cand.models[0].error +
                                    ". The full output is in " + in_quotes(c.layout.log));
  return cand;
}

// A copy of `database` without matches, so the matcher (which skips pairs it has) runs again
// on the same features.
void copy_features_only(const fs::path& database, const fs::path& copy) {
  std::error_code ec;
  fs::copy_file(database, copy, fs::copy_options::overwrite_existing, ec);
  if (ec) fail(SfmErrorKind::OutputExists, "cannot copy " + in_quotes(database) + ": " + ec.message());
  try {
    forget_matches(copy);
  } catch (const std::exception& e) {
    fail(SfmErrorKind::StageFailed, e.what());
  }
}

}  // namespace

bool Ladder::enough() const { return best.registered() >= kEscalateBelowShare * c.num_photos; }

fs::path Ladder::step_folder(const std::string& name) const {
  return c.layout.out / "attempts" / (std::to_string(attempts.size()) + "-" + name);
}

void Ladder::record(const std::string& step, const std::vector<std::string>& settings, const Candidate& cand,
                    double seconds) {
  attempts.push_back({step, joined(settings), cand.registered(), cand.points(), seconds});
  c.log << "\n######## desplat_sfm: step '" << step << "' (" << joined(settings) << "): " << cand.registered() << " of "
        << c.num_photos << " photos, " << cand.points() << " points, " << seconds << " s\n"
        << std::flush;
  if (better(cand, best)) best = cand;
}

void Ladder::read_capture_evidence() {
  const Stopwatch clock;
  try {
    capture = summarize_capture(read_capture_geometry(c.layout.database));
  } catch (const std::exception& e) {
    capture = CaptureEvidence{};
    capture.summary = std::string("not read (") + e.what() + ")";
  }
  evidence_seconds = clock.seconds();
  char share[96];
  std::snprintf(share, sizeof share, "%d of %d strong pairs move within 18 deg of the viewing direction",
                capture.forward_pairs, capture.strong_pairs);
  if (capture.forward)
    mapper_reason = std::string("forward walk: ") + share +
                    " (at least half), so colmap's defaults would refuse them as a start and drop the points "
                    "ahead of the camera; the mapper allows forward motion (init_max_forward_motion 1.0) and small "
                    "angles (init_min_tri_angle 2, tri_min_angle 0.5) and places a photo with 15 inliers, "
                    "starting from 50";
  else if (capture.read)
    mapper_reason = std::string("colmap's defaults: ") + share + " (fewer than half: not a forward walk)";
  else
    mapper_reason = "colmap's defaults: the capture evidence could not be read";
  c.log << "\n######## desplat_sfm: capture evidence (" << evidence_seconds << " s): " << capture.summary
        << "\n######## desplat_sfm: mapper: " << mapper_reason << "\n"
        << std::flush;
}

void Ladder::first_run(const std::string& camera_text) {
  const Stopwatch clock;
  const Workspace w{c.layout.database, c.layout.sparse_root};
  extract_seconds = run_extraction(c, o, w, single_camera, {}).seconds;
  match_seconds = run_matching(c, o, w, {}).seconds;
  read_capture_evidence();
  const std::vector<std::string> none;
  const std::vector<std::string>& mapper = capture.forward ? kForwardMapper : none;
  best = run_mapper(c, o, w, min_registered, mapper, &last_map);
  map_seconds = last_map.seconds;
  std::string settings = camera_text + ", " + matcher_name(c.matcher) + " matching";
  if (capture.forward) settings += ", " + joined(kForwardMapper);
  attempts.push_back({capture.forward ? "forward walk" : "colmap defaults", settings, best.registered(), best.points(),
                      clock.seconds()});
}

const std::vector<std::string>& Ladder::relaxed_mapper_settings() const {
  return capture.forward ? kForwardRelaxedMapper : kRelaxedMapper;
}

void Ladder::relaxed_mapper() {
  const Stopwatch clock;
  const Workspace w{best.where.database, step_folder("relaxed-mapper") / "sparse"};
  const Candidate cand = run_mapper(c, o, w, min_registered, relaxed_mapper_settings(), &last_map);
  record(kStepRelaxedMapper, relaxed_mapper_settings(), cand, clock.seconds());
}

void Ladder::register_the_rest() {
  if (best.registered() == 0) return;
  const Stopwatch clock;
  const std::vector<std::string>& settings = capture.forward ? kForwardRegistration : kRelaxedRegistration;
  const Candidate cand = register_rest(c, o, best, step_folder("register-rest"), settings);
  record(kStepRegisterRest, settings, cand, clock.seconds());
}

bool Ladder::matching_can_help() {
  std::map<std::string, MatchEvidence> evidence;
  try {
    evidence = read_match_evidence(best.where.database.empty() ? c.layout.database : best.where.database);
  } catch (const std::exception&) {
    return true;  // nothing known: the steps may help
  }
  const std::set<std::string> none;
  const std::set<std::string>& placed = best.models.empty() ? none : best.models[0].image_names;
  int lost = 0, lacking = 0;
  for (const fs::path& p : photos) {
    const std::string name = p.generic_string();
    if (placed.count(name)) continue;
    ++lost;
    const auto it = evidence.find(name);
    if (it == evidence.end() || lacks_matches(it->second)) ++lacking;
  }
  if (lacking > 0) return true;
  char counts[160];
  std::snprintf(counts, sizeof counts,
                "each of the %d photo(s) not placed has verified matches with at least %d photos (%d+ inliers each)",
                lost, kPlaceableMinPartners, kPlaceableInliers);
  stopped = counts;
  stopped += ": the mapper refused them, so matching again (guided matching, more features) cannot help. Try ";
  stopped += capture.forward
                 ? "photos a step apart that also move sideways or turn a little (walking straight ahead, the "
                   "points ahead are seen under tiny angles), or --camera-model SIMPLE_RADIAL (fewer lens "
                   "parameters to calibrate)"
                 : "--camera-model SIMPLE_RADIAL (fewer lens parameters to calibrate), photos a step apart with "
                   "more overlap, or, for photos taken walking forward, colmap mapper by hand on " +
                       in_quotes(c.layout.database) + " with " + joined(kForwardMapper);
  c.log << "\n######## desplat_sfm: escalation stopped: " << stopped << "\n" << std::flush;
  return false;
}

// Guided matching and the relaxed mapper, on a copy of the first run's features or, with
// `new_features`, on features extracted again with those options.
void Ladder::match_again(const char* step, const std::string& folder_name,
                         const std::vector<std::string>* new_features) {
  const Stopwatch clock;
  const fs::path folder = step_folder(folder_name);
  const Workspace w{folder / "database.db", folder / "sparse"};
  fs::create_directories(folder);
  std::vector<std::string> settings;
  if (new_features) {
    run_extraction(c, o, w, single_camera, *new_features);
    settings = *new_features;
  } else {
    copy_features_only(c.layout.database, w.database);
  }
  run_matching(c, o, w, kGuidedMatching);
  settings.insert(settings.end(), kGuidedMatching.begin(), kGuidedMatching.end());
  const std::vector<std::string>& mapper = relaxed_mapper_settings();
  settings.insert(settings.end(), mapper.begin(), mapper.end());
  const Candidate cand = run_mapper(c, o, w, min_registered, mapper, &last_map);
  record(step, settings, cand, clock.seconds());
}

void Ladder::guided_matching() { match_again(kStepGuidedMatching, "guided-matching", nullptr); }
void Ladder::more_features() { match_again(kStepMoreFeatures, "more-features", &kMoreFeatures); }

std::string Ladder::step_name(Step step) {
  if (step == &Ladder::relaxed_mapper) return kStepRelaxedMapper;
  if (step == &Ladder::register_the_rest) return kStepRegisterRest;
  if (step == &Ladder::guided_matching) return kStepGuidedMatching;
  return kStepMoreFeatures;
}

void Ladder::run() {
  const Step steps[] = {&Ladder::relaxed_mapper,    &Ladder::register_the_rest, &Ladder::guided_matching,
                        &Ladder::register_the_rest, &Ladder::more_features,     &Ladder::register_the_rest};
  for (const Step step : steps) {
    if (enough()) return;
    if ((step == &Ladder::guided_matching || step == &Ladder::more_features) && !matching_can_help()) return;
    const size_t before = attempts.size();
    try {
      (this->*step)();
    } catch (const SfmError& e) {
      // A step that fails or runs past its time limit ends the escalation; the models found
      // so far are kept (a long run never loses work to a later, optional step).
      if (e.kind() != SfmErrorKind::TimedOut && e.kind() != SfmErrorKind::StageFailed &&
          e.kind() != SfmErrorKind::NoModel)
        throw;
      const std::string what = e.what();
      if (attempts.size() == before) attempts.push_back({step_name(step), "", 0, 0, 0});
      attempts.back().settings +=
          std::string(attempts.back().settings.empty() ? "" : "; ") + "stopped: " + what.substr(0, what.find('\n'));
      c.log << "\n######## desplat_sfm: escalation stopped: " << what << "\n" << std::flush;
      return;
    }
  }
}

Candidate install_winner(const Context& c, Candidate best) {
  const Layout& l = c.layout;
  if (best.where.sparse_root == l.sparse_root) return best;
  const fs::path keep = l.out / "attempts" / "0-colmap-defaults";
  std::error_code ec;
  fs::create_directories(keep, ec);
  const auto move = [&](const fs::path& from, const fs::path& to) {
    fs::rename(from, to, ec);
    if (ec)
      fail(SfmErrorKind::OutputExists, "cannot move " + in_quotes(from) + " to " + in_quotes(to) + ": " + ec.message());
  };
  move(l.sparse_root, keep / "sparse");
  move(best.where.sparse_root, l.sparse_root);
  if (best.where.database != l.database) {
    move(l.database, keep / "database.db");
    move(best.where.database, l.database);
  }
  return Candidate{{l.database, l.sparse_root}, collect_models(l.sparse_root)};
}

}  // namespace desplat::sfm::pipeline
