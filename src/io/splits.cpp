// Train/test split rules; see include/desplat/io/splits.hpp for each rule's definition.
#include "desplat/io/splits.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>

namespace desplat {
namespace {

namespace fs = std::filesystem;

std::string file_name(const std::string& name) {
  const size_t slash = name.rfind('/');
  return slash == std::string::npos ? name : name.substr(slash + 1);
}

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  const size_t b = s.find_first_not_of(ws);
  if (b == std::string::npos) return {};
  return s.substr(b, s.find_last_not_of(ws) - b + 1);
}

std::vector<std::string> read_lines(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw SplitError(path.string() + ": cannot read the split file");
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  if (in.bad()) throw SplitError(path.string() + ": error while reading the split file");
  return lines;
}

std::map<std::string, size_t> index_by_name(const std::vector<std::string>& names) {
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < names.size(); ++i)
    if (!index.emplace(names[i], i).second) throw SplitError("image name '" + names[i] + "' appears twice");
  return index;
}

// Gives every image a list names the list's role; a name in both lists is an error. `lines`
// come from the file `source` (its name prefixes errors) or, when it is empty, from a caller.
void apply_list(const std::vector<std::string>& lines, const fs::path& source, ViewRole role,
                const std::map<std::string, size_t>& index, std::vector<std::optional<ViewRole>>& roles) {
  for (size_t n = 0; n < lines.size(); ++n) {
    const std::string name = trim(lines[n]);
    if (name.empty() || name[0] == '#') continue;
    const std::string at = source.empty() ? std::string(role == ViewRole::Train ? "train" : "test") + " list: "
                                          : source.string() + ":" + std::to_string(n + 1) + ": ";
    const auto it = index.find(name);
    if (it == index.end()) throw SplitError(at + "'" + name + "' is not a registered image of the model");
    auto& slot = roles[it->second];
    if (slot && *slot != role) throw SplitError(at + "'" + name + "' is in both the train and the test list");
    slot = role;
  }
}

std::vector<ViewRole> every_nth(const std::vector<std::string>& names, int n) {
  std::vector<size_t> order(names.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return names[a] < names[b]; });
  std::vector<ViewRole> roles(names.size());
  for (size_t pos = 0; pos < order.size(); ++pos)
    roles[order[pos]] = pos % static_cast<size_t>(n) == 0 ? ViewRole::Test : ViewRole::Train;
  return roles;
}

std::vector<ViewRole> name_lists(const std::vector<std::string>& names, const SplitOptions& o) {
  const bool has_train = !o.train_list.empty() || o.train_names.has_value();
  const bool has_test = !o.test_list.empty() || o.test_names.has_value();
  if (!has_train && !has_test) throw SplitError("split rule 'lists' needs a train list, a test list or both");
  if ((!o.train_list.empty() && o.train_names) || (!o.test_list.empty() && o.test_names))
    throw SplitError("split rule 'lists': give each list as a file or as names, not both");
  const auto index = index_by_name(names);
  std::vector<std::optional<ViewRole>> roles(names.size());
  if (!o.train_list.empty()) apply_list(read_lines(o.train_list), o.train_list, ViewRole::Train, index, roles);
  if (o.train_names) apply_list(*o.train_names, {}, ViewRole::Train, index, roles);
  if (!o.test_list.empty()) apply_list(read_lines(o.test_list), o.test_list, ViewRole::Test, index, roles);
  if (o.test_names) apply_list(*o.test_names, {}, ViewRole::Test, index, roles);
  const ViewRole rest = !has_train ? ViewRole::Train : !has_test ? ViewRole::Test : ViewRole::Unused;
  std::vector<ViewRole> out;
  for (const auto& r : roles) out.push_back(r.value_or(rest));
  return out;
}

enum class RobustKind { Clean, Clutter, Extra };

RobustKind robust_kind(const std::string& name) {
  const std::string base = file_name(name);
  const bool clean = base.find("clean") != std::string::npos;
  const bool clutter = base.find("clutter") != std::string::npos;
  const bool extra = base.find("extra") != std::string::npos;
  if (clean + clutter + extra != 1)
    throw SplitError("RobustNeRF split: image '" + name + "' must contain exactly one of 'clean', 'clutter', 'extra'");
  return clean ? RobustKind::Clean : clutter ? RobustKind::Clutter : RobustKind::Extra;
}

std::vector<ViewRole> robustnerf(const std::vector<std::string>& names, std::optional<double> ratio) {
  std::vector<ViewRole> roles(names.size(), ViewRole::Unused);
  std::vector<size_t> clean, clutter;
  for (size_t i = 0; i < names.size(); ++i) {
    const RobustKind kind = robust_kind(names[i]);
    if (kind == RobustKind::Extra) roles[i] = ViewRole::Test;
    if (kind == RobustKind::Clean) clean.push_back(i);
    if (kind == RobustKind::Clutter) clutter.push_back(i);
  }
  if (!ratio) {
    for (size_t i : clutter) roles[i] = ViewRole::Train;
    return roles;
  }
  const auto by_name = [&](size_t a, size_t b) { return names[a] < names[b]; };
  std::sort(clean.begin(), clean.end(), by_name);
  std::sort(clutter.begin(), clutter.end(), by_name);
  const size_t n = std::min(clean.size(), clutter.size());
  const size_t m = static_cast<size_t>(std::floor(static_cast<double>(n) * *ratio));
  for (size_t k = 0; k < n; ++k) {
    const bool cluttered = (k + 1) * m / n > k * m / n;
    roles[cluttered ? clutter[k] : clean[k]] = ViewRole::Train;
  }
  return roles;
}

std::vector<ViewRole> onthego(const std::vector<std::string>& names) {
  std::vector<ViewRole> roles;
  for (const auto& name : names)
    roles.push_back(file_name(name).find("extra") != std::string::npos ? ViewRole::Test : ViewRole::Train);
  return roles;
}

std::vector<std::string> split_tabs(const std::string& line) {
  std::vector<std::string> cells;
  std::stringstream s(line);
  for (std::string cell; std::getline(s, cell, '\t');) cells.push_back(trim(cell));
  if (!line.empty() && line.back() == '\t') cells.emplace_back();
  return cells;
}

std::vector<ViewRole> phototourism(const std::vector<std::string>& names, const fs::path& tsv) {
  const std::vector<std::string> lines = read_lines(tsv);
  if (lines.empty()) throw SplitError(tsv.string() + ": empty .tsv file (expected a header line)");
  const std::vector<std::string> header = split_tabs(trim(lines[0]));
  const auto column = [&](const std::string& want) {
    const auto it = std::find(header.begin(), header.end(), want);
    if (it == header.end()) throw SplitError(tsv.string() + ":1: the header has no '" + want + "' column");
    return static_cast<size_t>(it - header.begin());
  };
  const size_t c_file = column("filename"), c_id = column("id"), c_split = column("split");
  const auto index = index_by_name(names);
  std::vector<std::optional<ViewRole>> roles(names.size());
  for (size_t n = 1; n < lines.size(); ++n) {
    if (trim(lines[n]).empty()) continue;
    const std::string at = tsv.string() + ":" + std::to_string(n + 1) + ": ";
    const std::vector<std::string> cells = split_tabs(lines[n]);
    if (cells.size() < header.size())
      throw SplitError(at + "expected " + std::to_string(header.size()) + " tab-separated columns, got " +
                       std::to_string(cells.size()));
    const std::string& id = cells[c_id];
    if (id.empty() || id == "nan" || id == "NaN") continue;
    const std::string& split = cells[c_split];
    if (split != "train" && split != "test")
      throw SplitError(at + "split must be 'train' or 'test', got '" + split + "'");
    const auto it = index.find(cells[c_file]);
    if (it == index.end()) throw SplitError(at + "'" + cells[c_file] + "' is not a registered image of the model");
    const ViewRole role = split == "train" ? ViewRole::Train : ViewRole::Test;
    auto& slot = roles[it->second];
    if (slot && *slot != role) throw SplitError(at + "'" + cells[c_file] + "' is listed as both train and test");
    slot = role;
  }
  std::vector<ViewRole> out;
  for (const auto& r : roles) out.push_back(r.value_or(ViewRole::Unused));
  return out;
}

}  // namespace

const char* split_rule_name(SplitRule rule) {
  switch (rule) {
    case SplitRule::EveryNth:
      return "every-nth";
    case SplitRule::AllTrain:
      return "all-train";
    case SplitRule::NameLists:
      return "lists";
    case SplitRule::RobustNeRF:
      return "robustnerf";
    case SplitRule::OnTheGo:
      return "onthego";
    case SplitRule::PhotoTourism:
      return "phototourism";
  }
  return "?";
}

namespace {

// Options that belong to another rule are a mistake on the caller's side, not ignored.
void check_options(const SplitOptions& o) {
  const std::string rule = std::string("split rule '") + split_rule_name(o.rule) + "'";
  if (o.rule != SplitRule::EveryNth && o.every_nth != SplitOptions{}.every_nth)
    throw SplitError(rule + " does not use every_nth (only 'every-nth' does)");
  if (o.rule == SplitRule::EveryNth && o.every_nth < 2)
    throw SplitError("every_nth must be at least 2, got " + std::to_string(o.every_nth));
  if (o.rule != SplitRule::NameLists &&
      (!o.train_list.empty() || !o.test_list.empty() || o.train_names || o.test_names))
    throw SplitError(rule + " does not use train/test lists (only 'lists' does)");
  if (o.rule != SplitRule::RobustNeRF && o.clutter_ratio)
    throw SplitError(rule + " does not use clutter_ratio (only 'robustnerf' does)");
  if (o.clutter_ratio && !(*o.clutter_ratio >= 0 && *o.clutter_ratio <= 1))
    throw SplitError("clutter_ratio must be in [0, 1], got " + std::to_string(*o.clutter_ratio));
  if (o.rule != SplitRule::PhotoTourism && !o.tsv.empty())
    throw SplitError(rule + " does not use a .tsv file (only 'phototourism' does)");
  if (o.rule == SplitRule::PhotoTourism && o.tsv.empty()) throw SplitError(rule + " needs a .tsv file");
}

}  // namespace

SplitRule split_rule_from_name(const std::string& name) {
  for (SplitRule r : {SplitRule::EveryNth, SplitRule::AllTrain, SplitRule::NameLists, SplitRule::RobustNeRF,
                      SplitRule::OnTheGo, SplitRule::PhotoTourism})
    if (name == split_rule_name(r)) return r;
  throw SplitError("unknown split rule '" + name +
                   "' (expected every-nth, all-train, lists, robustnerf, onthego or phototourism)");
}

std::vector<ViewRole> assign_split(const std::vector<std::string>& names, const SplitOptions& options) {
  check_options(options);
  std::vector<ViewRole> roles;
  switch (options.rule) {
    case SplitRule::EveryNth:
      roles = every_nth(names, options.every_nth);
      break;
    case SplitRule::AllTrain:
      roles.assign(names.size(), ViewRole::Train);
      break;
    case SplitRule::NameLists:
      roles = name_lists(names, options);
      break;
    case SplitRule::RobustNeRF:
      roles = robustnerf(names, options.clutter_ratio);
      break;
    case SplitRule::OnTheGo:
      roles = onthego(names);
      break;
    case SplitRule::PhotoTourism:
      roles = phototourism(names, options.tsv);
      break;
  }
  const auto train = std::count(roles.begin(), roles.end(), ViewRole::Train);
  if (train == 0)
    throw SplitError(std::string("split rule '") + split_rule_name(options.rule) + "' leaves no training view among " +
                     std::to_string(names.size()) + " images");
  return roles;
}

}  // namespace desplat
