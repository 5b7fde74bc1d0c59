// Structure from motion by running the colmap executable; see include/desplat/sfm/sfm.hpp.
#include "desplat/sfm/sfm.hpp"
#include "desplat/io/output_folder.hpp"

#include <OpenImageIO/imageio.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string_view>

#include "desplat/core/stopwatch.hpp"
#include "desplat/io/colmap.hpp"
#include "desplat/io/jpeg_end.hpp"
#include "desplat/sfm/subprocess.hpp"
#include "sfm/match_evidence.hpp"
#include "sfm/progress.hpp"
#include "sfm/quoting.hpp"

extern char** environ;

namespace desplat::sfm {
namespace fs = std::filesystem;

namespace {


[[noreturn]] void fail(SfmErrorKind kind, const std::string& message) { throw SfmError(kind, message); }

std::string seconds_text(double s) {  // "0.5", "3675"
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", s);
  return buf;
}

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

// ---- Output folder -----------------------------------------------------------------------

struct Layout {
  fs::path out, images, database, sparse_root, log, image_list;
  explicit Layout(const fs::path& o)
      : out(o), images(o / "images"), database(o / "database.db"), sparse_root(o / "sparse"), log(o / "colmap.log"),
        image_list(o / "image_list.txt") {}
};

bool is_inside(const fs::path& inner, const fs::path& outer) {
  const fs::path a = fs::weakly_canonical(inner), b = fs::weakly_canonical(outer);
  auto [end_b, end_a] = std::mismatch(b.begin(), b.end(), a.begin(), a.end());
  return end_b == b.end();
}

// Earlier results are only replaced on request: a mapper run can take hours.
void clear_earlier_results(const Layout& l, bool overwrite) {
  std::error_code ec;
  const fs::path earlier[] = {l.database, l.sparse_root};
  for (const fs::path& p : earlier) {
    if (!fs::exists(fs::symlink_status(p, ec))) continue;
    if (!overwrite)
      fail(SfmErrorKind::OutputExists,
           in_quotes(l.out) + " holds results of an earlier run (" + p.filename().string() +
               "); pass --overwrite to redo structure from motion there, or choose another --out");
    fs::remove_all(p, ec);
    if (ec) fail(SfmErrorKind::OutputExists, "cannot remove " + in_quotes(p) + ": " + ec.message());
  }
  for (const char* suffix : {"-wal", "-shm", "-journal"}) fs::remove(l.database.string() + suffix, ec);
}

void copy_photos(const fs::path& from, const fs::path& to, const std::vector<fs::path>& photos) {
  std::error_code ec;
  for (const fs::path& rel : photos) {
    fs::create_directories((to / rel).parent_path(), ec);
    if (!ec) fs::copy_file(from / rel, to / rel, fs::copy_options::overwrite_existing, ec);
    if (ec)
      fail(SfmErrorKind::OutputExists,
           "cannot copy " + in_quotes(from / rel) + " to " + in_quotes(to / rel) + ": " + ec.message());
  }
}

// <out>/images: the input itself, a symlink to it, or a copy of its photos.
void provide_images(const SfmOptions& o, const Layout& l, const std::vector<fs::path>& photos) {
  std::error_code ec;
  const auto st = fs::symlink_status(l.images, ec);
  if (fs::exists(st)) {
    if (fs::equivalent(l.images, o.images, ec)) return;  // the input already is <out>/images
    if (!fs::is_symlink(st))
      fail(SfmErrorKind::OutputExists,
           in_quotes(l.images) + " already exists and is not the images folder; remove it or choose another --out");
    fs::remove(l.images, ec);  // a stale link from an earlier run: removing it loses no data
  }
  if (o.copy_images) return copy_photos(o.images, l.images, photos);
  fs::create_directory_symlink(fs::canonical(o.images), l.images, ec);
  if (ec)
    fail(SfmErrorKind::OutputExists, "cannot create the symlink " + in_quotes(l.images) + ": " + ec.message() +
                                         "; pass --copy-images to copy the photos instead");
}

void write_image_list(const fs::path& path, const std::vector<fs::path>& photos) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  for (const fs::path& p : photos) f << p.generic_string() << '\n';
  if (!f.flush()) fail(SfmErrorKind::OutputExists, "cannot write " + in_quotes(path));
}

void prepare_output(const SfmOptions& o, const Layout& l, const std::vector<fs::path>& photos) {
  std::error_code ec;
  if (is_inside(o.out, o.images))
    fail(SfmErrorKind::OutputExists, "--out " + in_quotes(o.out) + " is inside the images folder " +
                                         in_quotes(o.images) + "; choose an --out outside it");
  try {
    check_output_folder("--out", o.out, {{"--images", o.images}});
  } catch (const std::invalid_argument& e) {
    fail(SfmErrorKind::OutputExists, e.what());
  }
  fs::create_directories(o.out, ec);
  if (ec || !fs::is_directory(o.out))
    fail(SfmErrorKind::OutputExists,
         "cannot create the output folder " + in_quotes(o.out) + (ec ? ": " + ec.message() : ""));
  clear_earlier_results(l, o.overwrite);
  provide_images(o, l, photos);
  write_image_list(l.image_list, photos);
}

// ---- Stages ------------------------------------------------------------------------------

struct Context {
  fs::path colmap;
  Layout layout;
  std::ofstream log;
  ProgressFn on_progress;
  int num_photos = 0;
  Matcher matcher = Matcher::Exhaustive;  // as resolved
  std::optional<double> fixed_time_limit;  // SfmOptions::stage_time_limit_s

  double time_limit(SfmStage stage) const {
    return fixed_time_limit ? *fixed_time_limit : default_stage_time_limit(stage, matcher, num_photos);
  }
};

void report(const Context& c, const SfmProgress& p) {
  if (c.on_progress) c.on_progress(p);
}

struct StageOutput {
  ProcessExit exit;
  double seconds = 0;
  double time_limit = 0;  // s
  std::deque<std::string> tail;  // last non-blank lines
  SfmProgress last;
};

std::string command_line(const std::vector<std::string>& argv) {
  std::string s;
  for (const std::string& a : argv) s += (s.empty() ? "" : " ") + a;
  return s;
}

// One colmap command; `total`/`unit` seed the progress until colmap reports its own.
StageOutput run_stage(Context& c, SfmStage stage, const std::string& command, std::vector<std::string> args, int total,
                      const char* unit = "image") {
  args.insert(args.begin(), {c.colmap.string(), command});
  c.log << "\n######## desplat_sfm: colmap " << command << "\n$ " << command_line(args) << "\n" << std::flush;
  ProgressParser parser(stage, total, unit);
  report(c, parser.current());
  StageOutput out;
  auto on_line = [&](std::string_view line) {
    if (line.find_first_not_of(" \t") == std::string_view::npos) return;
    out.tail.emplace_back(line);
    if (out.tail.size() > 12) out.tail.pop_front();
    if (parser.feed(line)) report(c, parser.current());
  };
  LineSplitter lines;
  const Stopwatch clock;
  out.time_limit = c.time_limit(stage);
  try {
    out.exit = run_subprocess(args, [&](std::string_view chunk) {
      c.log.write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
      c.log.flush();  // so `tail -f colmap.log` follows along
      lines.feed(chunk, on_line);
    }, out.time_limit);
  } catch (const SubprocessError& e) {
    fail(SfmErrorKind::StageFailed, e.what());
  }
  lines.finish(on_line);
  out.seconds = clock.seconds();
  c.log << "\n######## colmap " << command << " "
        << (out.exit.how == ProcessExit::How::TimedOut   ? "stopped at its time limit"
            : out.exit.how == ProcessExit::How::Signaled ? "killed by signal " + std::to_string(out.exit.code)
                                                         : "exited with code " + std::to_string(out.exit.code))
        << " after " << out.seconds << " s\n"
        << std::flush;
  out.last = parser.current();
  return out;
}

std::string tail_text(const StageOutput& s) {
  if (s.tail.empty()) return "  (it printed nothing)\n";
  std::string t;
  for (const std::string& line : s.tail) t += "  | " + line + "\n";
  return t;
}

[[noreturn]] void stage_failed(const Context& c, const std::string& command, const StageOutput& s) {
  std::string what;
  if (s.exit.how == ProcessExit::How::TimedOut) {
    fail(SfmErrorKind::TimedOut,
         "colmap " + command + " ran past its time limit of " + seconds_text(s.time_limit) + " s for " +
             std::to_string(c.num_photos) + " photos and was stopped. Its last lines:\n" + tail_text(s) +
             "The full output is in " + in_quotes(c.layout.log) +
             ". Try fewer or smaller photos, --matcher sequential for a video-like capture, or a longer "
             "limit with --stage-time-limit SECONDS.");
  }
  if (s.exit.how == ProcessExit::How::Signaled) {
    what = "was killed by signal " + std::to_string(s.exit.code) + " (" + strsignal(s.exit.code) + ")";
    if (s.exit.code == SIGKILL) what += "; if the machine ran out of memory, try fewer --threads or smaller photos";
  } else {
    what = "failed with exit code " + std::to_string(s.exit.code);
  }
  fail(SfmErrorKind::StageFailed, "colmap " + command + " " + what + ". Its last lines:\n" + tail_text(s) +
                                      "The full output is in " + in_quotes(c.layout.log));
}

void finish_stage(Context& c, const std::string& command, const StageOutput& s) {
  if (!s.exit.ok()) stage_failed(c, command, s);
  SfmProgress done = s.last;
  done.finished = true;
  if (done.total > 0) done.done = done.total;
  report(c, done);
}

std::string threads(int n) { return std::to_string(n); }

// Where one try at a model reads and writes: the first run uses <out>/database.db and
// <out>/sparse; an escalation step that matches again has its own folder under attempts/.
struct Workspace {
  fs::path database, sparse_root;
};

std::vector<std::string> extract_args(const SfmOptions& o, const Layout& l, const Workspace& w, bool single_camera,
                                      const std::vector<std::string>& extra) {
  const std::string model = o.camera_model.empty() ? auto_camera_model(single_camera) : o.camera_model;
  std::vector<std::string> a = {"--database_path", w.database.string(), "--image_path", l.images.string(),
                                "--image_list_path", l.image_list.string(), "--ImageReader.camera_model",
                                model, "--ImageReader.single_camera", single_camera ? "1" : "0",
                                "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads",
                                threads(o.num_threads), "--log_to_stderr", "1"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

// About 25 blocks, so the matching progress moves; the set of image pairs is the same.
int exhaustive_block_size(int num_photos) { return std::clamp((num_photos + 4) / 5, 10, 50); }

std::vector<std::string> match_args(const SfmOptions& o, const Workspace& w, Matcher m, int num_photos,
                                    const std::vector<std::string>& extra) {
  std::vector<std::string> a = {"--database_path", w.database.string(), "--SiftMatching.use_gpu", "0",
                                "--SiftMatching.num_threads", threads(o.num_threads), "--log_to_stderr", "1"};
  if (m == Matcher::Exhaustive)
    a.insert(a.end(), {"--ExhaustiveMatching.block_size", std::to_string(exhaustive_block_size(num_photos))});
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

// colmap drops sub-models smaller than min(10, #photos); a lower floor keeps a small
// partial model so the user hears "only N of M" (and can accept it) instead of "no model".
std::vector<std::string> map_args(const SfmOptions& o, const Layout& l, const Workspace& w, int min_registered,
                                  const std::vector<std::string>& extra) {
  std::vector<std::string> a = {"--database_path", w.database.string(), "--image_path", l.images.string(),
                                "--output_path", w.sparse_root.string(), "--Mapper.num_threads",
                                threads(o.num_threads), "--Mapper.min_model_size",
                                std::to_string(std::min(min_registered, 3)), "--log_to_stderr", "1"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

StageOutput run_extraction(Context& c, const SfmOptions& o, const Workspace& w, bool single_camera,
                           const std::vector<std::string>& extra) {
  StageOutput out = run_stage(c, SfmStage::Extract, "feature_extractor",
                              extract_args(o, c.layout, w, single_camera, extra), c.num_photos);
  finish_stage(c, "feature_extractor", out);
  return out;
}

StageOutput run_matching(Context& c, const SfmOptions& o, const Workspace& w, const std::vector<std::string>& extra) {
  const Matcher m = c.matcher;
  const std::string command = std::string(matcher_name(m)) + "_matcher";
  auto args = match_args(o, w, m, c.num_photos, extra);
  StageOutput out;
  if (m != Matcher::Exhaustive) {
    out = run_stage(c, SfmStage::Match, command, std::move(args), c.num_photos);
  } else {
    const int block = exhaustive_block_size(c.num_photos), blocks = (c.num_photos + block - 1) / block;
    out = run_stage(c, SfmStage::Match, command, std::move(args), blocks * blocks, "block");
  }
  finish_stage(c, command, out);
  return out;
}

// ---- Models ------------------------------------------------------------------------------

struct ModelInfo {
  fs::path dir;
  int registered = -1;  // -1: unreadable
  int points = 0;
  std::set<std::string> image_names;  // as colmap wrote them: relative to images/, '/'-separated
  double mean_track_length = 0, mean_reprojection_error = 0;  // over its 3D points [images], [px]
  std::string error;  // why it is unreadable
};

bool is_number(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char ch) { return std::isdigit(ch); });
}

// mapper's numbered model folders, largest first (ties: lower number first).
std::vector<ModelInfo> collect_models(const fs::path& sparse_root) {
  std::vector<std::pair<long, ModelInfo>> found;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(sparse_root, ec)) {
    const std::string name = e.path().filename().string();
    if (!e.is_directory(ec) || !is_number(name) || name.size() > 9) continue;
    ModelInfo info;
    info.dir = e.path();
    try {
      const colmap::Model m = colmap::read_model_binary(e.path());
      info.registered = static_cast<int>(m.images.size());
      info.points = static_cast<int>(m.points.size());
      for (const auto& [id, image] : m.images) info.image_names.insert(image.name);
      for (const auto& [id, point] : m.points) {
        info.mean_track_length += double(point.track.size()) / double(m.points.size());
        info.mean_reprojection_error += point.error / double(m.points.size());
      }
    } catch (const colmap::ColmapError& err) {
      info.error = err.what();  // ranked last; it keeps a numbered folder so nothing is lost
    }
    found.emplace_back(std::stol(name), info);
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) {
    return a.second.registered != b.second.registered ? a.second.registered > b.second.registered : a.first < b.first;
  });
  std::vector<ModelInfo> models;
  for (auto& f : found) models.push_back(f.second);
  return models;
}

// Renames the ranked models to sparse/0, sparse/1, … (via temporary names, so no clashes).
void renumber_models(std::vector<ModelInfo>& models, const fs::path& sparse_root) {
  std::error_code ec;
  for (size_t i = 0; i < models.size(); ++i) {
    const fs::path tmp = sparse_root / (".renumber_" + std::to_string(i));
    fs::rename(models[i].dir, tmp, ec);
    if (ec) fail(SfmErrorKind::OutputExists, "cannot rename " + in_quotes(models[i].dir) + ": " + ec.message());
    models[i].dir = tmp;
  }
  for (size_t i = 0; i < models.size(); ++i) {
    const fs::path final_dir = sparse_root / std::to_string(i);
    fs::rename(models[i].dir, final_dir, ec);
    if (ec) fail(SfmErrorKind::OutputExists, "cannot rename " + in_quotes(models[i].dir) + ": " + ec.message());
    models[i].dir = final_dir;
  }
}

const char* kPhotoAdvice =
    "take more overlapping photos: every part of the scene in at least 3 sharp photos, taken a step apart "
    "(not from one spot), with texture in view";

// What the chosen matcher assumes, when that may be why photos were not connected.
std::string matcher_hint(Matcher m) {
  if (m == Matcher::Sequential)
    return " Sequential matching assumes the file names are in capture order; if not, use --matcher exhaustive.";
  if (m == Matcher::Spatial)
    return " Spatial matching pairs photos by the GPS positions in their EXIF data; without those nothing is "
           "matched: use --matcher exhaustive or sequential.";
  return "";
}

// colmap 3.8's mapper exits 1 with this when it has nothing to write (exit 1 alone could
// also be, e.g., a bad option).
bool said_no_model(const StageOutput& s) {
  return std::any_of(s.tail.begin(), s.tail.end(), [](const std::string& line) {
    return line.find("failed to create sparse model") != std::string::npos;
  });
}

[[noreturn]] void no_model(const Context& c, Matcher m, const StageOutput& s) {
  fail(SfmErrorKind::NoModel, "colmap could not build a model: no two of the " + std::to_string(c.num_photos) +
                                  " photos matched well enough to start a reconstruction; " + kPhotoAdvice + "." +
                                  matcher_hint(m) + " colmap mapper's last lines:\n" + tail_text(s) +
                                  "The full output is in " + in_quotes(c.layout.log));
}

// Fewer features than this rarely give the 30 inliers colmap's mapper needs to place a photo
// (Mapper.abs_pose_min_num_inliers); a photo below it is blurred, textureless or tiny.
constexpr int kFewFeatures = 100;

// Why colmap did not put `name` in the largest model, from the other models and the database.
std::string why_not_placed(const std::string& name, const std::vector<ModelInfo>& models,
                           const std::map<std::string, MatchEvidence>* evidence) {
  for (size_t k = 1; k < models.size(); ++k)
    if (models[k].image_names.count(name))
      return "placed in a separate model (" + models[k].dir.filename().string() + ", " +
             std::to_string(models[k].registered) +
             " photos) that colmap could not join to the largest: too few matches between the two groups";
  if (!evidence) return "not in the model (colmap's database could not be read)";
  const auto it = evidence->find(name);
  if (it == evidence->end()) return "colmap did not add it to its database (it could not read the photo)";
  const MatchEvidence& e = it->second;
  const std::string features = std::to_string(e.features) + " features";
  if (e.features < kFewFeatures) return "too few features (" + features + "): blurred, textureless or very small?";
  if (e.matched_photos == 0) return features + ", but no verified match with any other photo (no overlap?)";
  return features + ", verified matches with " + std::to_string(e.matched_photos) + " photo(s) (at most " +
         std::to_string(e.best_inliers) + "), but too few to the placed photos for the mapper to place it";
}

std::vector<SkippedFile> photos_not_in(const std::vector<ModelInfo>& models, const std::vector<fs::path>& photos,
                                       const fs::path& database) {
  std::vector<SkippedFile> missing;
  for (const fs::path& p : photos)
    if (!models[0].image_names.count(p.generic_string())) missing.push_back({p, ""});
  if (missing.empty()) return missing;  // nothing to explain: the database is not read
  std::map<std::string, MatchEvidence> evidence;
  bool have_evidence = true;
  try {
    evidence = read_match_evidence(database);
  } catch (const std::exception&) {
    have_evidence = false;
  }
  for (SkippedFile& m : missing)
    m.reason = why_not_placed(m.path.generic_string(), models, have_evidence ? &evidence : nullptr);
  return missing;
}

// The largest share of photos, rounded down to a hundredth, that `registered` of `n` meets.
std::string share_text(int registered, int n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", std::floor(100.0 * registered / std::max(1, n)) / 100.0);
  return buf;
}

void check_registered(const Context& c, const std::vector<ModelInfo>& models, const fs::path& database,
                      int min_registered, const std::vector<fs::path>& photos, const std::vector<SfmAttempt>& attempts) {
  const ModelInfo& best = models[0];
  if (best.registered >= min_registered) return;
  SfmResult lost;
  lost.num_photos = c.num_photos;
  std::string tried;
  for (const SfmAttempt& a : attempts) tried += (tried.empty() ? "" : ", ") + a.step + " " + std::to_string(a.registered);
  lost.unregistered = photos_not_in(models, photos, database);
  std::string names = describe_lost_photos(lost);
  if (!names.empty() && names.back() == '\n') names.pop_back();
  const std::string accept =
      best.registered >= 3 ? "; to use it anyway, run again with --overwrite --min-registered-share " +
                                 share_text(best.registered, c.num_photos)
                           : "";
  fail(SfmErrorKind::TooFewRegistered,
       "only " + std::to_string(best.registered) + " of " + std::to_string(c.num_photos) +
           " photos could be placed (at least " + std::to_string(min_registered) + " needed); " + kPhotoAdvice + "." +
           matcher_hint(c.matcher) + " Photos placed by each step: " + tried + ". The partial model is kept in " +
           in_quotes(best.dir) + accept +
           ". Details: " + in_quotes(c.layout.log) + "\n" + names);
}

// ---- Escalation ---------------------------------------------------------------------------
//
// colmap's defaults are made for thousands of features per photo over wide baselines. A
// capture that registers fewer than kEscalateBelowShare of its photos gets the steps below, in
// order of cost, until one reaches that share; the model with the most photos wins.

// colmap starts a model from a pair with 100 inliers and 16° of triangulation angle and adds a
// photo with 30 inliers. Small or low-texture photos, narrow baselines and collections with few
// shared features have no such pair. A third to a half of each still leaves tens of inliers,
// far above the 5 a two-view pose needs, so a wrong start stays unlikely (the reprojection
// error of the result is reported).
const std::vector<std::string> kRelaxedMapper = {"--Mapper.init_min_num_inliers", "30", "--Mapper.init_min_tri_angle",
                                                 "4", "--Mapper.abs_pose_min_num_inliers", "15"};
// Registering into a finished model uses the same per-photo threshold.
const std::vector<std::string> kRelaxedRegistration = {"--Mapper.abs_pose_min_num_inliers", "15"};
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

std::string joined(const std::vector<std::string>& args) {
  std::string s;
  for (const std::string& a : args) s += (s.empty() ? "" : " ") + a;
  return s;
}

// One try's models, ranked largest first.
struct Candidate {
  Workspace where;
  std::vector<ModelInfo> models;
  int registered() const { return models.empty() ? 0 : std::max(0, models[0].registered); }
  int points() const { return models.empty() ? 0 : models[0].points; }
};

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
Candidate register_rest(Context& c, const SfmOptions& o, const Candidate& from, const fs::path& folder) {
  const Workspace w{from.where.database, folder / "sparse"};
  const fs::path model = w.sparse_root / "0";
  std::error_code ec;
  fs::create_directories(model, ec);
  std::vector<std::string> reg = {"--database_path", w.database.string(), "--input_path",
                                  from.models[0].dir.string(), "--output_path", model.string(),
                                  "--Mapper.num_threads", threads(o.num_threads), "--log_to_stderr", "1"};
  reg.insert(reg.end(), kRelaxedRegistration.begin(), kRelaxedRegistration.end());
  const StageOutput r = run_stage(c, SfmStage::Map, "image_registrator", std::move(reg), c.num_photos);
  if (!r.exit.ok()) stage_failed(c, "image_registrator", r);
  const StageOutput ba =
      run_stage(c, SfmStage::Map, "bundle_adjuster",
                {"--input_path", model.string(), "--output_path", model.string(), "--log_to_stderr", "1"}, c.num_photos);
  if (!ba.exit.ok()) stage_failed(c, "bundle_adjuster", ba);
  Candidate cand{w, collect_models(w.sparse_root)};
  if (!cand.models.empty() && cand.models[0].registered < 0)
    fail(SfmErrorKind::NoModel, "colmap image_registrator wrote a model that cannot be read: " +
                                    cand.models[0].error + ". The full output is in " + in_quotes(c.layout.log));
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

struct Ladder {
  Ladder(Context& context, const SfmOptions& options, int min_registered_photos, bool single)
      : c(context), o(options), min_registered(min_registered_photos), single_camera(single) {}

  Context& c;
  const SfmOptions& o;
  int min_registered;
  bool single_camera;
  std::vector<SfmAttempt> attempts;
  Candidate best;
  StageOutput last_map;
  double extract_seconds = 0, match_seconds = 0, map_seconds = 0;  // of the first run

  bool enough() const { return best.registered() >= kEscalateBelowShare * c.num_photos; }

  fs::path step_folder(const std::string& name) const {
    return c.layout.out / "attempts" / (std::to_string(attempts.size()) + "-" + name);
  }

  void record(const std::string& step, const std::vector<std::string>& settings, const Candidate& cand,
              double seconds) {
    attempts.push_back({step, joined(settings), cand.registered(), cand.points(), seconds});
    c.log << "\n######## desplat_sfm: step '" << step << "' (" << joined(settings) << "): " << cand.registered()
          << " of " << c.num_photos << " photos, " << cand.points() << " points, " << seconds << " s\n"
          << std::flush;
    if (better(cand, best)) best = cand;
  }

  void first_run(const std::string& camera_text) {
    const Stopwatch clock;
    const Workspace w{c.layout.database, c.layout.sparse_root};
    extract_seconds = run_extraction(c, o, w, single_camera, {}).seconds;
    match_seconds = run_matching(c, o, w, {}).seconds;
    best = run_mapper(c, o, w, min_registered, {}, &last_map);
    map_seconds = last_map.seconds;
    attempts.push_back({"colmap defaults", camera_text + ", " + matcher_name(c.matcher) + " matching",
                        best.registered(), best.points(), clock.seconds()});
  }

  void relaxed_mapper() {
    const Stopwatch clock;
    const Workspace w{best.where.database, step_folder("relaxed-mapper") / "sparse"};
    const Candidate cand = run_mapper(c, o, w, min_registered, kRelaxedMapper, &last_map);
    record(kStepRelaxedMapper, kRelaxedMapper, cand, clock.seconds());
  }

  void register_the_rest() {
    if (best.registered() == 0) return;
    const Stopwatch clock;
    const Candidate cand = register_rest(c, o, best, step_folder("register-rest"));
    record(kStepRegisterRest, kRelaxedRegistration, cand, clock.seconds());
  }

  // Guided matching and the relaxed mapper, on a copy of the first run's features or, with
  // `new_features`, on features extracted again with those options.
  void match_again(const char* step, const std::string& folder_name, const std::vector<std::string>* new_features) {
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
    settings.insert(settings.end(), kRelaxedMapper.begin(), kRelaxedMapper.end());
    const Candidate cand = run_mapper(c, o, w, min_registered, kRelaxedMapper, &last_map);
    record(step, settings, cand, clock.seconds());
  }

  void guided_matching() { match_again(kStepGuidedMatching, "guided-matching", nullptr); }
  void more_features() { match_again(kStepMoreFeatures, "more-features", &kMoreFeatures); }

  using Step = void (Ladder::*)();
  static std::string step_name(Step step) {
    if (step == &Ladder::relaxed_mapper) return kStepRelaxedMapper;
    if (step == &Ladder::register_the_rest) return kStepRegisterRest;
    if (step == &Ladder::guided_matching) return kStepGuidedMatching;
    return kStepMoreFeatures;
  }

  void run() {
    const Step steps[] = {&Ladder::relaxed_mapper,  &Ladder::register_the_rest, &Ladder::guided_matching,
                          &Ladder::register_the_rest, &Ladder::more_features,   &Ladder::register_the_rest};
    for (const Step step : steps) {
      if (enough()) return;
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
        attempts.back().settings += std::string(attempts.back().settings.empty() ? "" : "; ") +
                                    "stopped: " + what.substr(0, what.find('\n'));
        c.log << "\n######## desplat_sfm: escalation stopped: " << what << "\n" << std::flush;
        return;
      }
    }
  }
};

// Puts the winning step's models in <out>/sparse (and its database in <out>/database.db); what
// they replace moves to attempts/0-colmap-defaults, so nothing is deleted.
Candidate install_winner(const Context& c, Candidate best) {
  const Layout& l = c.layout;
  if (best.where.sparse_root == l.sparse_root) return best;
  const fs::path keep = l.out / "attempts" / "0-colmap-defaults";
  std::error_code ec;
  fs::create_directories(keep, ec);
  const auto move = [&](const fs::path& from, const fs::path& to) {
    fs::rename(from, to, ec);
    if (ec) fail(SfmErrorKind::OutputExists, "cannot move " + in_quotes(from) + " to " + in_quotes(to) + ": " + ec.message());
  };
  move(l.sparse_root, keep / "sparse");
  move(best.where.sparse_root, l.sparse_root);
  if (best.where.database != l.database) {
    move(l.database, keep / "database.db");
    move(best.where.database, l.database);
  }
  return Candidate{{l.database, l.sparse_root}, collect_models(l.sparse_root)};
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
    case Matcher::Auto: return "auto";
    case Matcher::Exhaustive: return "exhaustive";
    case Matcher::Sequential: return "sequential";
    case Matcher::Spatial: return "spatial";
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
    case SfmStage::Extract: return 300 + 30 * n;
    case SfmStage::Match: return matcher == Matcher::Exhaustive ? 600 + 3 * n * (n - 1) / 2 : 600 + 60 * n;
    case SfmStage::Map: return 600 + 60 * n;
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
  for (const SfmAttempt& a : r.attempts) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-18s %d of %d photos, %d points, %.0f s", (a.step + ":").c_str(),
                  a.registered, r.num_photos, a.points, a.seconds);
    text += line + std::string(" (") + a.settings + ")\n";
  }
  if (!r.warning.empty()) text += "warning: " + r.warning + "\n";
  return text;
}

SfmResult run_sfm(const SfmOptions& o) {
  const Stopwatch clock;
  if (!o.camera_model.empty()) check_camera_model(o.camera_model);
  if (o.stage_time_limit_s && !(*o.stage_time_limit_s > 0))
    fail(SfmErrorKind::BadOptions, "the stage time limit must be positive, got " + std::to_string(*o.stage_time_limit_s) + " s");
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
  c.log << "######## desplat_sfm: " << num_photos << " photos; " << cameras.reason << "\n######## matching: "
        << matcher_reason << "\n" << std::flush;

  Ladder ladder{c, o, min_registered, cameras.single};
  const std::string model = o.camera_model.empty() ? auto_camera_model(cameras.single) : o.camera_model;
  ladder.first_run((cameras.single ? "one shared camera, " : "one camera per photo, ") + model);
  if (o.escalate) ladder.run();
  if (ladder.best.registered() == 0) no_model(c, matcher, ladder.last_map);
  Candidate best = install_winner(c, ladder.best);
  renumber_models(best.models, c.layout.sparse_root);
  check_registered(c, best.models, c.layout.database, min_registered, scan.photos, ladder.attempts);

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
  return r;
}

}  // namespace desplat::sfm
