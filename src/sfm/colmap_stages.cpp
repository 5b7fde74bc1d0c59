// One colmap stage as a subprocess (see src/sfm/pipeline.hpp): its command line, everything it
// prints into colmap.log, progress parsed from its output, a time limit, and one clear error
// when it fails.
#include <signal.h>

#include <algorithm>
#include <cstring>
#include <string_view>

#include "desplat/core/stopwatch.hpp"
#include "sfm/pipeline.hpp"
#include "sfm/progress.hpp"
#include "sfm/quoting.hpp"

namespace desplat::sfm::pipeline {
namespace fs = std::filesystem;
namespace {

std::string seconds_text(double s) {  // "0.5", "3675"
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", s);
  return buf;
}

void finish_stage(Context& c, const std::string& command, const StageOutput& s) {
  if (!s.exit.ok()) stage_failed(c, command, s);
  SfmProgress done = s.last;
  done.finished = true;
  if (done.total > 0) done.done = done.total;
  report(c, done);
}

std::vector<std::string> extract_args(const SfmOptions& o, const Layout& l, const Workspace& w, bool single_camera,
                                      const std::vector<std::string>& extra) {
  const std::string model = o.camera_model.empty() ? auto_camera_model(single_camera) : o.camera_model;
  std::vector<std::string> a = {"--database_path",
                                w.database.string(),
                                "--image_path",
                                l.images.string(),
                                "--image_list_path",
                                l.image_list.string(),
                                "--ImageReader.camera_model",
                                model,
                                "--ImageReader.single_camera",
                                single_camera ? "1" : "0",
                                "--SiftExtraction.use_gpu",
                                "0",
                                "--SiftExtraction.num_threads",
                                threads(o.num_threads),
                                "--log_to_stderr",
                                "1"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

// About 25 blocks, so the matching progress moves; the set of image pairs is the same.
int exhaustive_block_size(int num_photos) { return std::clamp((num_photos + 4) / 5, 10, 50); }

std::vector<std::string> match_args(const SfmOptions& o, const Workspace& w, Matcher m, int num_photos,
                                    const std::vector<std::string>& extra) {
  std::vector<std::string> a = {"--database_path",
                                w.database.string(),
                                "--SiftMatching.use_gpu",
                                "0",
                                "--SiftMatching.num_threads",
                                threads(o.num_threads),
                                "--log_to_stderr",
                                "1"};
  if (m == Matcher::Exhaustive)
    a.insert(a.end(), {"--ExhaustiveMatching.block_size", std::to_string(exhaustive_block_size(num_photos))});
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

}  // namespace

std::string joined(const std::vector<std::string>& args) {
  std::string s;
  for (const std::string& a : args) s += (s.empty() ? "" : " ") + a;
  return s;
}

StageOutput run_stage(Context& c, SfmStage stage, const std::string& command, std::vector<std::string> args, int total,
                      const char* unit) {
  args.insert(args.begin(), {c.colmap.string(), command});
  c.log << "\n######## desplat_sfm: colmap " << command << "\n$ " << joined(args) << "\n" << std::flush;
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
    out.exit = run_subprocess(
        args,
        [&](std::string_view chunk) {
          c.log.write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
          c.log.flush();  // so `tail -f colmap.log` follows along
          lines.feed(chunk, on_line);
        },
        out.time_limit);
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

std::string threads(int n) { return std::to_string(n); }

// Where one try at a model reads and writes: the first run uses <out>/database.db and
// <out>/sparse; an escalation step that matches again has its own folder under attempts/.
// colmap drops sub-models smaller than min(10, #photos); a lower floor keeps a small
// partial model so the user hears "only N of M" (and can accept it) instead of "no model".
std::vector<std::string> map_args(const SfmOptions& o, const Layout& l, const Workspace& w, int min_registered,
                                  const std::vector<std::string>& extra) {
  std::vector<std::string> a = {"--database_path",
                                w.database.string(),
                                "--image_path",
                                l.images.string(),
                                "--output_path",
                                w.sparse_root.string(),
                                "--Mapper.num_threads",
                                threads(o.num_threads),
                                "--Mapper.min_model_size",
                                std::to_string(std::min(min_registered, 3)),
                                "--log_to_stderr",
                                "1"};
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

}  // namespace desplat::sfm::pipeline
