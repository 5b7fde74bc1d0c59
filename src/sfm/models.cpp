// The models colmap's mapper wrote (see src/sfm/pipeline.hpp): ranked, renumbered, and for
// every photo the largest one lacks, the reason the other models and the database give.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>

#include "desplat/io/colmap.hpp"
#include "sfm/match_evidence.hpp"
#include "sfm/pipeline.hpp"
#include "sfm/quoting.hpp"

namespace desplat::sfm::pipeline {
namespace fs = std::filesystem;
namespace {

bool is_number(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char ch) { return std::isdigit(ch); });
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

// The largest share of photos, rounded down to a hundredth, that `registered` of `n` meets.
std::string share_text(int registered, int n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", std::floor(100.0 * registered / std::max(1, n)) / 100.0);
  return buf;
}

}  // namespace

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

void check_registered(const Context& c, const std::vector<ModelInfo>& models, const fs::path& database,
                      int min_registered, const std::vector<fs::path>& photos, const std::vector<SfmAttempt>& attempts,
                      const std::string& stopped) {
  const ModelInfo& best = models[0];
  if (best.registered >= min_registered) return;
  SfmResult lost;
  lost.num_photos = c.num_photos;
  std::string tried;
  for (const SfmAttempt& a : attempts)
    tried += (tried.empty() ? "" : ", ") + a.step + " " + std::to_string(a.registered);
  lost.unregistered = photos_not_in(models, photos, database);
  std::string names = describe_lost_photos(lost);
  if (!names.empty() && names.back() == '\n') names.pop_back();
  const std::string accept = best.registered >= 3
                                 ? "; to use it anyway, run again with --overwrite --min-registered-share " +
                                       share_text(best.registered, c.num_photos)
                                 : "";
  fail(SfmErrorKind::TooFewRegistered,
       "only " + std::to_string(best.registered) + " of " + std::to_string(c.num_photos) +
           " photos could be placed (at least " + std::to_string(min_registered) + " needed); " + kPhotoAdvice + "." +
           matcher_hint(c.matcher) + " Photos placed by each step: " + tried + "." +
           (stopped.empty() ? "" : " The escalation stopped early: " + stopped) + " The partial model is kept in " +
           in_quotes(best.dir) + accept + ". Details: " + in_quotes(c.layout.log) + "\n" + names);
}

}  // namespace desplat::sfm::pipeline
