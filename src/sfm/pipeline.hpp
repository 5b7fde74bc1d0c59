// The pieces run_sfm (src/sfm/sfm.cpp) is made of, private to the sfm layer: the output
// folder (output_folder.cpp), one colmap stage as a subprocess with its log and progress
// (colmap_stages.cpp), the models mapper wrote and why photos are missing from them
// (models.cpp), and the escalation steps tried when too few photos are placed (escalation.cpp).
// Every failure is an SfmError (include/desplat/sfm/sfm.hpp) with one message saying what to do.
#pragma once

#include <deque>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "desplat/sfm/sfm.hpp"
#include "desplat/sfm/subprocess.hpp"

namespace desplat::sfm::pipeline {

[[noreturn]] inline void fail(SfmErrorKind kind, const std::string& message) { throw SfmError(kind, message); }

// ---- Output folder (output_folder.cpp) -------------------------------------------------------

// Where a run writes, under SfmOptions::out (the layout in sfm.hpp).
struct Layout {
  std::filesystem::path out, images, database, sparse_root, log, image_list;
  explicit Layout(const std::filesystem::path& o)
      : out(o),
        images(o / "images"),
        database(o / "database.db"),
        sparse_root(o / "sparse"),
        log(o / "colmap.log"),
        image_list(o / "image_list.txt") {}
};

// Creates `out`, refuses an --out inside the images folder, clears an earlier run's results
// (only with overwrite), provides <out>/images and writes image_list.txt.
void prepare_output(const SfmOptions& o, const Layout& l, const std::vector<std::filesystem::path>& photos);

// ---- Stages (colmap_stages.cpp) --------------------------------------------------------------

// What every stage of one run shares.
struct Context {
  std::filesystem::path colmap;
  Layout layout;
  std::ofstream log;
  ProgressFn on_progress;
  int num_photos = 0;
  Matcher matcher = Matcher::Exhaustive;   // as resolved
  std::optional<double> fixed_time_limit;  // SfmOptions::stage_time_limit_s

  double time_limit(SfmStage stage) const {
    return fixed_time_limit ? *fixed_time_limit : default_stage_time_limit(stage, matcher, num_photos);
  }
};

inline void report(const Context& c, const SfmProgress& p) {
  if (c.on_progress) c.on_progress(p);
}

struct StageOutput {
  ProcessExit exit;
  double seconds = 0;
  double time_limit = 0;         // s
  std::deque<std::string> tail;  // last non-blank lines
  SfmProgress last;
};

// Where one try at a model reads and writes: the first run uses <out>/database.db and
// <out>/sparse; an escalation step that matches again has its own folder under attempts/.
struct Workspace {
  std::filesystem::path database, sparse_root;
};

// One colmap command, logged; `total`/`unit` seed the progress until colmap reports its own.
StageOutput run_stage(Context& c, SfmStage stage, const std::string& command, std::vector<std::string> args, int total,
                      const char* unit = "image");
// The stage's last lines, indented, for a message.
std::string tail_text(const StageOutput& s);
// TimedOut or StageFailed, with the stage's last lines and where the full log is.
[[noreturn]] void stage_failed(const Context& c, const std::string& command, const StageOutput& s);
// Feature extraction and matching for workspace `w`, colmap's options plus `extra`; a stage
// that does not exit 0 is stage_failed.
StageOutput run_extraction(Context& c, const SfmOptions& o, const Workspace& w, bool single_camera,
                           const std::vector<std::string>& extra);
StageOutput run_matching(Context& c, const SfmOptions& o, const Workspace& w, const std::vector<std::string>& extra);
// The mapper's arguments for workspace `w`.
std::vector<std::string> map_args(const SfmOptions& o, const Layout& l, const Workspace& w, int min_registered,
                                  const std::vector<std::string>& extra);
std::string threads(int n);  // colmap's --*.num_threads value
// The arguments separated by single spaces, for the log ("colmap mapper --database_path …").
std::string joined(const std::vector<std::string>& args);

// ---- Models (models.cpp) ---------------------------------------------------------------------

struct ModelInfo {
  std::filesystem::path dir;
  int registered = -1;  // -1: unreadable
  int points = 0;
  std::set<std::string> image_names;  // as colmap wrote them: relative to images/, '/'-separated
  double mean_track_length = 0, mean_reprojection_error = 0;  // over its 3D points [images], [px]
  std::string error;                                          // why it is unreadable
};

// mapper's numbered model folders under `sparse_root`, largest first (ties: lower number first).
std::vector<ModelInfo> collect_models(const std::filesystem::path& sparse_root);
// Renames the ranked models to sparse/0, sparse/1, … (via temporary names, so no clashes).
void renumber_models(std::vector<ModelInfo>& models, const std::filesystem::path& sparse_root);
// The photos models[0] lacks, each with the reason the other models and the database give.
std::vector<SkippedFile> photos_not_in(const std::vector<ModelInfo>& models,
                                       const std::vector<std::filesystem::path>& photos,
                                       const std::filesystem::path& database);
// TooFewRegistered (the model kept) unless models[0] holds at least `min_registered` photos.
// `stopped`: why the escalation ended early (empty when it did not).
void check_registered(const Context& c, const std::vector<ModelInfo>& models, const std::filesystem::path& database,
                      int min_registered, const std::vector<std::filesystem::path>& photos,
                      const std::vector<SfmAttempt>& attempts, const std::string& stopped);
// Whether the mapper said it had no model to write (colmap exits 1 then).
bool said_no_model(const StageOutput& s);
// NoModel, with the mapper's last lines and advice for the photos and the matcher.
[[noreturn]] void no_model(const Context& c, Matcher m, const StageOutput& s);

// ---- Escalation (escalation.cpp) -------------------------------------------------------------

// One try's models, ranked largest first.
struct Candidate {
  Workspace where;
  std::vector<ModelInfo> models;
  int registered() const { return models.empty() ? 0 : std::max(0, models[0].registered); }
  int points() const { return models.empty() ? 0 : models[0].points; }
};

// The first run, then (run()) the escalation steps in order of cost until one places
// kEscalateBelowShare of the photos; `best` is the model with the most photos. The first run
// reads the capture evidence after matching and picks the mapper thresholds from it; the steps
// that match again run only while some photo left out lacks verified matches.
struct Ladder {
  Ladder(Context& context, const SfmOptions& options, int min_registered_photos, bool single,
         const std::vector<std::filesystem::path>& photo_list)
      : c(context), o(options), min_registered(min_registered_photos), single_camera(single), photos(photo_list) {}

  Context& c;
  const SfmOptions& o;
  int min_registered;
  bool single_camera;
  const std::vector<std::filesystem::path>& photos;  // as handed to colmap, relative to images/
  std::vector<SfmAttempt> attempts;
  Candidate best;
  StageOutput last_map;
  double extract_seconds = 0, match_seconds = 0, map_seconds = 0;  // of the first run
  double evidence_seconds = 0;
  CaptureEvidence capture;
  std::string mapper_reason;  // which mapper thresholds the first run used, and why
  std::string stopped;        // why the escalation ended before its last step, with what to try

  // Extraction, matching, the capture evidence, then the mapper with the thresholds it suits,
  // into <out>/database.db and <out>/sparse.
  void first_run(const std::string& camera_text);
  // The escalation steps; a step that fails or runs past its time limit ends them, keeping the
  // models found so far.
  void run();

 private:
  bool enough() const;
  std::filesystem::path step_folder(const std::string& name) const;
  void record(const std::string& step, const std::vector<std::string>& settings, const Candidate& cand, double seconds);
  void read_capture_evidence();
  // False (with `stopped` set) when every photo left out has verified matches enough to be
  // placed: matching again cannot add what the mapper refused.
  bool matching_can_help();
  const std::vector<std::string>& relaxed_mapper_settings() const;
  void relaxed_mapper();
  void register_the_rest();
  void match_again(const char* step, const std::string& folder_name, const std::vector<std::string>* new_features);
  void guided_matching();
  void more_features();
  using Step = void (Ladder::*)();
  static std::string step_name(Step step);
};

// Puts the winning step's models in <out>/sparse (and its database in <out>/database.db); what
// they replace moves to attempts/0-colmap-defaults, so nothing is deleted.
Candidate install_winner(const Context& c, Candidate best);

}  // namespace desplat::sfm::pipeline
