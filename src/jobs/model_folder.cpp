// A trained model's folder: config.json (with the scene recipe), checkpoint, metrics.
#include "desplat/jobs/model_folder.hpp"
#include "desplat/io/json_text.hpp"

#include <algorithm>
#include <fstream>
#include <stdexcept>

#include "desplat/io/atomic_file.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/training_checkpoint.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

json read_json_file(const fs::path& path, const std::string& what) {
  std::ifstream f(path);
  if (!f) throw std::invalid_argument(what + ": cannot read " + path.string());
  try {
    return parse_json_bounded(f, path.string());
  } catch (const json::exception& e) {
    throw std::invalid_argument(path.string() + " is not valid JSON: " + e.what());
  }
}

// A JSON library message without its "[json.exception.…] " tag.
std::string plain(const json::exception& e) {
  const std::string text = e.what();
  const size_t tag_end = text.find("] ");
  return tag_end == std::string::npos ? text : text.substr(tag_end + 2);
}

std::string join(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// The first names of `a` missing from `b`, for messages.
std::string missing(const std::vector<std::string>& a, const std::vector<std::string>& b) {
  std::vector<std::string> out;
  for (const std::string& n : a)
    if (std::find(b.begin(), b.end(), n) == b.end() && out.size() < 3) out.push_back(n);
  return join(out);
}

}  // namespace

SceneRecipe SceneRecipe::of(const Scene& scene, const fs::path& data_dir, const SceneOptions& options) {
  SceneRecipe r;
  r.data_dir = fs::absolute(data_dir).lexically_normal();
  r.downscale = options.downscale;
  r.split = options.split;
  for (fs::path* p : {&r.split.train_list, &r.split.test_list, &r.split.tsv})
    if (!p->empty()) *p = fs::absolute(*p).lexically_normal();
  for (const SceneView& v : scene.views) (v.is_test ? r.test_views : r.train_views).push_back(v.name);
  r.masks_dir = scene.masks_dir;
  return r;
}

SceneOptions SceneRecipe::reopen_options() const {
  SceneOptions o;
  o.downscale = downscale;
  if (train_views.empty()) {  // a model from before the outcome was recorded: its rule as it was
    o.split = split;
    return o;
  }
  o.split.rule = SplitRule::NameLists;
  o.split.train_names = train_views;  // both given: every other registered image stays Unused
  o.split.test_names = test_views;
  return o;
}

std::string SceneRecipe::difference(const SceneRecipe& other) const {
  if (fs::weakly_canonical(data_dir) != fs::weakly_canonical(other.data_dir))
    return "the data folder was " + data_dir.string() + ", now " + other.data_dir.string();
  if (downscale != other.downscale)
    return "--downscale was " + std::to_string(downscale) + ", now " + std::to_string(other.downscale);
  if (train_views.empty()) return "";  // an older model recorded no views: nothing more to compare
  if (train_views != other.train_views) {
    const std::string gone = missing(train_views, other.train_views), added = missing(other.train_views, train_views);
    return "the training views differ (" + std::to_string(train_views.size()) + " then, " +
           std::to_string(other.train_views.size()) + " now" + (gone.empty() ? "" : "; no longer: " + gone) +
           (added.empty() ? "" : "; new: " + added) + ")";
  }
  if (test_views != other.test_views)
    return "the test views differ (" + std::to_string(test_views.size()) + " then, " +
           std::to_string(other.test_views.size()) + " now)";
  if (masks_dir != other.masks_dir)
    return "the masks were " + (masks_dir.empty() ? std::string("none") : masks_dir.string()) + ", now " +
           (other.masks_dir.empty() ? std::string("none") : other.masks_dir.string());
  return "";
}

json SceneRecipe::to_json() const {
  json split_json = {{"rule", split_rule_name(split.rule)}};
  if (split.rule == SplitRule::EveryNth) split_json["every_nth"] = split.every_nth;
  if (!split.train_list.empty()) split_json["train_list"] = split.train_list.string();
  if (!split.test_list.empty()) split_json["test_list"] = split.test_list.string();
  if (split.train_names) split_json["train_names"] = *split.train_names;
  if (split.test_names) split_json["test_names"] = *split.test_names;
  if (split.clutter_ratio) split_json["clutter_ratio"] = *split.clutter_ratio;
  if (!split.tsv.empty()) split_json["tsv"] = split.tsv.string();
  json j = {{"data_dir", data_dir.string()},
            {"downscale", downscale},
            {"split", split_json},
            {"train_views", train_views},
            {"test_views", test_views}};
  if (!masks_dir.empty()) j["masks_dir"] = masks_dir.string();
  return j;
}

SceneRecipe SceneRecipe::from_json(const json& j) {
  SceneRecipe r;
  try {
    r.data_dir = j.at("data_dir").get<std::string>();
    r.downscale = j.at("downscale").get<int>();
    const json& s = j.at("split");
    r.split.rule = split_rule_from_name(s.at("rule").get<std::string>());
    r.split.every_nth = s.value("every_nth", SplitOptions{}.every_nth);
    r.split.train_list = s.value("train_list", std::string());
    r.split.test_list = s.value("test_list", std::string());
    if (s.contains("train_names")) r.split.train_names = s.at("train_names").get<std::vector<std::string>>();
    if (s.contains("test_names")) r.split.test_names = s.at("test_names").get<std::vector<std::string>>();
    if (s.contains("clutter_ratio")) r.split.clutter_ratio = s.at("clutter_ratio").get<double>();
    r.split.tsv = s.value("tsv", std::string());
    r.train_views = j.at("train_views").get<std::vector<std::string>>();
    r.test_views = j.at("test_views").get<std::vector<std::string>>();
    r.masks_dir = j.value("masks_dir", std::string());
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("the scene recipe is damaged (") + plain(e) + "): train the model again");
  } catch (const SplitError& e) {
    throw std::invalid_argument(std::string("scene recipe: ") + e.what());
  }
  if (r.downscale < 1) throw std::invalid_argument("scene recipe: downscale must be at least 1");
  if (r.train_views.empty()) throw std::invalid_argument("scene recipe: no training views");
  return r;
}

void ModelFolder::write_config(const Config& c) const {
  write_file_atomically(config_path(),
                        json{{"train", config_to_json(c.train)}, {"scene", c.scene.to_json()}, {"run", c.run}}.dump(2));
}

json ModelFolder::read_config_json() const { return read_json_file(config_path(), "not a desplat model folder"); }

ModelFolder::Config ModelFolder::read_config() const {
  const json j = read_config_json();
  const std::string file = config_path().string();
  const std::string what_to_do = "point at a folder desplat_train wrote, or train the model again";
  if (!j.is_object())
    throw std::invalid_argument(file + " is not a desplat config.json (its top level is " + j.type_name() +
                                ", not an object): " + what_to_do);
  if (!j.contains("train"))
    throw std::invalid_argument(file + " has no \"train\" settings, so desplat_train did not write it: " + what_to_do);
  if (!j.at("train").is_object())
    throw std::invalid_argument(file + ": \"train\" must be an object of settings (it is " + j.at("train").type_name() +
                                "): " + what_to_do);
  Config c;
  try {
    c.train = config_from_json(j.at("train"));
    c.unrecorded_settings = settings_absent_from(j.at("train"));
    c.run = j.value("run", json::object());
    if (!c.run.is_object())
      throw std::invalid_argument(std::string("\"run\" must be an object (it is ") + c.run.type_name() +
                                  "): " + what_to_do);
    if (j.contains("scene")) {
      c.scene = SceneRecipe::from_json(j.at("scene"));
      return c;
    }
    // Written before the recipe was recorded: the rule and every_nth were all it kept.
    const SplitRule rule = SplitRule(c.run.at("split_rule").get<int>());
    if (rule != SplitRule::EveryNth && rule != SplitRule::AllTrain)
      throw std::invalid_argument("it was written by an older desplat that did not record the '" +
                                  std::string(split_rule_name(rule)) + "' split's files; train it again to render it");
    c.scene.data_dir = c.run.at("data_dir").get<std::string>();
    c.scene.downscale = c.run.at("downscale").get<int>();
    c.scene.split.rule = rule;
    if (rule == SplitRule::EveryNth) c.scene.split.every_nth = c.run.at("split_every_nth").get<int>();
  } catch (const json::exception& e) {
    throw std::invalid_argument(file + " holds a damaged record (" + plain(e) + "): " + what_to_do);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(file + ": " + e.what());
  }
  return c;
}

void ModelFolder::write_checkpoint(const Trainer& trainer, const json& extra_metadata) const {
  desplat::write_checkpoint(checkpoint_path(), make_training_checkpoint(trainer, extra_metadata));
}

Checkpoint ModelFolder::read_checkpoint() const {
  if (!has_checkpoint()) throw std::invalid_argument("no checkpoint at " + checkpoint_path().string());
  return desplat::read_checkpoint(checkpoint_path());
}

void ModelFolder::write_metrics(const json& metrics) const { write_file_atomically(metrics_path(), metrics.dump(2)); }

json ModelFolder::read_metrics() const { return read_json_file(metrics_path(), "no metrics"); }

std::vector<std::filesystem::path> ModelFolder::existing_training_outputs() const {
  std::vector<std::filesystem::path> found;
  for (const char* name :
       {"config.json", "checkpoint.ckpt", "metrics.json", "point_cloud.ply", "renders", "report.html"})
    if (std::filesystem::exists(dir_ / name)) found.push_back(dir_ / name);
  return found;
}

void ModelFolder::remove_training_outputs() const {
  for (const std::filesystem::path& p : existing_training_outputs()) {
    std::error_code ec;
    std::filesystem::remove_all(p, ec);
    if (ec) throw std::invalid_argument("--overwrite: cannot remove " + p.string() + ": " + ec.message());
  }
}

}  // namespace desplat
