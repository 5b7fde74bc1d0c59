// TrainConfig ⇄ JSON, validation and comparison, all from the settings table
// (settings_table.hpp): no setting's name or range is written here.
#include "desplat/train/train_config_json.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <variant>

#include "train/settings_table.hpp"

namespace desplat {

// The action is written and read as its name; an unknown name is an error naming the setting.
void to_json(nlohmann::json& j, const TransientPointAction& a) { j = to_string(a); }
void from_json(const nlohmann::json& j, TransientPointAction& a) {
  if (!j.is_string())
    throw std::invalid_argument("config: init.transient_points must be a string (keep, drop or seed)");
  a = transient_point_action_from_string(j.get<std::string>());
}

// The pixel loops' instruction set, by name (raster.hpp, KernelIsa).
void to_json(nlohmann::json& j, const KernelIsa& isa) { j = kernel_isa_name(isa); }
void from_json(const nlohmann::json& j, KernelIsa& isa) {
  const auto parsed = j.is_string() ? parse_kernel_isa(j.get<std::string>()) : std::nullopt;
  if (!parsed)
    throw std::invalid_argument("config: kernel_isa must be auto, portable, avx2 or avx512 (got " + j.dump() + ")");
  isa = *parsed;
}

namespace {

using settings::Bounds;
using settings::Setting;

template <class T>
constexpr bool kIsInteger = std::is_integral_v<T> && !std::is_same_v<T, bool>;

nlohmann::json::json_pointer pointer(const std::string& dotted) {
  std::string p = "/" + dotted;
  for (char& ch : p)
    if (ch == '.') ch = '/';
  return nlohmann::json::json_pointer(p);
}

void collect_leaves(const nlohmann::json& j, const std::string& prefix, std::vector<std::string>& out) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string key = prefix.empty() ? it.key() : prefix + "." + it.key();
    if (it->is_object())
      collect_leaves(*it, key, out);
    else
      out.push_back(key);
  }
}

// A range end as a reader writes it: 10^18 for the cap, integers in full.
std::string show_end(double v) {
  if (v == 1e18) return "10^18";
  if (v >= 1.8446744073709552e19) return "18446744073709551615";
  char text[40];
  std::snprintf(text, sizeof text, "%.15g", v);
  return text;
}

// [lo, hi] of a setting of type T: the table's bounds within what T holds.
template <class T>
std::pair<double, double> ends(const Bounds& b) {
  if constexpr (kIsInteger<T>)
    return {std::max(b.lo, double(std::numeric_limits<T>::lowest())),
            std::min(b.hi, double(std::numeric_limits<T>::max()))};
  return {b.lo, b.hi};
}

// What a numeric setting of type T allows: "an integer in [1, 2147483647]", "a number in
// (0, 10^18] (0 freezes the group)".
template <class T>
std::string allowed(const Bounds& b) {
  const auto [lo, hi] = ends<T>(b);
  std::string text = std::string(kIsInteger<T> ? "an integer in " : "a number in ") + (b.lo_open ? "(" : "[") +
                     show_end(lo) + ", " + show_end(hi) + (b.hi_open ? ")" : "]");
  if (b.note) text += std::string(" (") + b.note + ")";
  return text;
}

// Throws "config: <name> must be <allowed> (got <got>)" unless `v` is finite, in the range
// and (for an integer setting) whole.
// `what` replaces the allowed range in the message (eval_background's "three numbers, each …").
template <class T>
void check_number(const char* name, const Bounds& b, long double v, const std::string& got,
                  const std::string& what = "") {
  // long double holds every 64-bit integer exactly: 10^18 + 1 is not 10^18.
  long double lo = b.lo, hi = b.hi;
  if constexpr (kIsInteger<T>) {
    lo = std::max(lo, (long double)std::numeric_limits<T>::lowest());
    hi = std::min(hi, (long double)std::numeric_limits<T>::max());
  }
  const bool ok = std::isfinite(v) && v >= lo && v <= hi && !(b.lo_open && v == lo) && !(b.hi_open && v == hi) &&
                  (!kIsInteger<T> || v == std::floor(v));
  if (!ok)
    throw std::invalid_argument(std::string("config: ") + name + " must be " + (what.empty() ? allowed<T>(b) : what) +
                                " (got " + got + ")");
}

std::string show_value(double v) {
  char text[40];
  std::snprintf(text, sizeof text, "%g", v);
  return text;
}

// The table's allowed values for `field` in words (docs/CONFIG.md's range column).
std::string range_of(const Setting& s) {
  return std::visit(
      [&](auto* p) -> std::string {
        using T = std::remove_pointer_t<decltype(p)>;
        if constexpr (std::is_same_v<T, bool>)
          return "true or false";
        else if constexpr (std::is_same_v<T, TransientPointAction>)
          return "keep, drop or seed";
        else if constexpr (std::is_same_v<T, KernelIsa>)
          return "auto, portable, avx2 or avx512";
        else if constexpr (std::is_same_v<T, std::array<float, 3>>)
          return "three numbers, each " + allowed<float>(s.bounds).substr(9);
        else
          return allowed<T>(s.bounds);
      },
      s.field);
}

std::string type_of(const Setting& s) {
  return std::visit(
      [](auto* p) -> std::string {
        using T = std::remove_pointer_t<decltype(p)>;
        if constexpr (std::is_same_v<T, bool>)
          return "boolean";
        else if constexpr (kIsInteger<T>)
          return "integer";
        else if constexpr (std::is_same_v<T, float>)
          return "number";
        else if constexpr (std::is_same_v<T, std::array<float, 3>>)
          return "[number, number, number]";
        else
          return "string";
      },
      s.field);
}

// Reads one setting from its JSON value, range-checking the value as written (before any
// conversion could wrap or round it).
template <class T>
void read_value(const Setting& s, const nlohmann::json& v, T& out) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean())
      throw std::invalid_argument(std::string("config: ") + s.name + " must be true or false (got " + v.dump() + ")");
    out = v.get<bool>();
  } else if constexpr (std::is_same_v<T, std::array<float, 3>>) {
    if (!v.is_array() || v.size() != 3 || !std::all_of(v.begin(), v.end(), [](const auto& e) { return e.is_number(); }))
      throw std::invalid_argument(std::string("config: ") + s.name + " must be " + range_of(s) + " (got " + v.dump() +
                                  ")");
    for (size_t k = 0; k < 3; ++k) {
      check_number<float>(s.name, s.bounds, v[k].get<double>(), v[k].dump(), range_of(s));
      out[k] = v[k].get<float>();
    }
  } else if constexpr (std::is_arithmetic_v<T>) {
    if (!v.is_number())
      throw std::invalid_argument(std::string("config: ") + s.name + " must be " + allowed<T>(s.bounds) + " (got " +
                                  v.dump() + ")");
    const long double value = v.is_number_unsigned()  ? (long double)v.get<uint64_t>()
                              : v.is_number_integer() ? (long double)v.get<int64_t>()
                                                      : (long double)v.get<double>();
    check_number<T>(s.name, s.bounds, value, v.dump());
    if constexpr (kIsInteger<T>)
      out = v.is_number_float() ? static_cast<T>(v.get<double>()) : v.get<T>();
    else
      out = v.get<T>();
  } else {
    out = v.get<T>();  // the enums' from_json above
  }
}

// `j` with every old name (settings::aliases) moved to today's.
nlohmann::json with_todays_names(const nlohmann::json& j) {
  nlohmann::json out = j;
  for (const settings::Alias& a : settings::aliases()) {
    const auto old_ptr = pointer(a.old_name), new_ptr = pointer(a.name);
    if (!out.contains(old_ptr)) continue;
    if (out.contains(new_ptr))
      throw std::invalid_argument(std::string("config: ") + a.old_name + " is the old name of " + a.name +
                                  " and both are given: keep only " + a.name);
    out[new_ptr] = out.at(old_ptr);
    out.at(old_ptr.parent_pointer()).erase(old_ptr.back());
  }
  return out;
}

}  // namespace

void validate_config(const TrainConfig& c) {
  TrainConfig copy = c;
  for (const Setting& s : settings::table(copy))
    std::visit(
        [&](auto* p) {
          using T = std::remove_pointer_t<decltype(p)>;
          if constexpr (std::is_same_v<T, std::array<float, 3>>) {
            for (const float v : *p) check_number<float>(s.name, s.bounds, v, show_value(v), range_of(s));
          } else if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
            check_number<T>(s.name, s.bounds, (long double)*p,
                            kIsInteger<T> ? std::to_string(*p) : show_value(double(*p)));
          }
        },
        s.field);
  // A batch holds at most one refinement of the static schedule (docs/METHOD.md §6, batches).
  if (c.batch > c.densify.refine_every)
    throw std::invalid_argument("config: batch must be at most densify.refine_every (" +
                                std::to_string(c.densify.refine_every) + "; got " + std::to_string(c.batch) +
                                "): a batch holds at most one refinement; use a smaller batch");
  if (!cpu_supports(c.kernel_isa))
    throw std::invalid_argument(std::string("config: kernel_isa ") + kernel_isa_name(c.kernel_isa) +
                                " is not supported by this CPU (or this build); use auto");
}

nlohmann::json config_to_json(const TrainConfig& c) {
  TrainConfig copy = c;
  nlohmann::json j = nlohmann::json::object();
  for (const Setting& s : settings::table(copy)) std::visit([&](auto* p) { j[pointer(s.name)] = *p; }, s.field);
  return j;
}

std::vector<std::string> config_differences(const TrainConfig& a, const TrainConfig& b, const std::string& b_name,
                                            const std::vector<std::string>& ignore) {
  const nlohmann::json ja = config_to_json(a), jb = config_to_json(b);
  // Settings are float32: 7 significant digits show them as written (0.08, not 0.0799999982).
  auto show = [](const nlohmann::json& v) {
    if (!v.is_number_float()) return v.dump();
    char text[32];
    std::snprintf(text, sizeof text, "%.7g", v.get<double>());
    return std::string(text);
  };
  TrainConfig names_only;
  std::vector<std::string> out;
  for (const Setting& s : settings::table(names_only)) {
    if (std::find(ignore.begin(), ignore.end(), s.name) != ignore.end()) continue;
    const auto ptr = pointer(s.name);
    if (ja.at(ptr) != jb.at(ptr))
      out.push_back(std::string(s.name) + " " + show(ja.at(ptr)) + " (" + show(jb.at(ptr)) + " in " + b_name + ")");
  }
  return out;
}

std::vector<std::string> settings_absent_from(const nlohmann::json& j) {
  const nlohmann::json named = j.is_object() ? with_todays_names(j) : nlohmann::json::object();
  TrainConfig names_only;
  std::vector<std::string> out;
  for (const Setting& s : settings::table(names_only))
    if (!named.contains(pointer(s.name))) out.push_back(s.name);
  return out;
}

TrainConfig config_from_json(const nlohmann::json& j, TrainConfig base) {
  if (!j.is_object()) throw std::invalid_argument("config: the top level must be a JSON object");
  const nlohmann::json named = with_todays_names(j);
  std::vector<std::string> leaves;
  collect_leaves(named, "", leaves);
  const std::vector<Setting> table = settings::table(base);
  for (const std::string& key : leaves)
    if (std::none_of(table.begin(), table.end(), [&](const Setting& s) { return key == s.name; }))
      throw std::invalid_argument("config: unknown setting '" + key + "' (docs/CONFIG.md lists every setting)");
  for (const Setting& s : table) {
    const auto ptr = pointer(s.name);
    if (!named.contains(ptr)) continue;
    std::visit([&](auto* p) { read_value(s, named.at(ptr), *p); }, s.field);
  }
  validate_config(base);
  return base;
}

std::vector<SettingDescription> describe_settings() {
  TrainConfig defaults;
  const nlohmann::json values = config_to_json(defaults);
  std::vector<SettingDescription> out;
  for (const Setting& s : settings::table(defaults)) {
    const nlohmann::json& v = values.at(pointer(s.name));
    std::string shown = v.dump();
    if (v.is_number_float()) {
      char text[32];
      std::snprintf(text, sizeof text, "%.7g", v.get<double>());
      shown = text;
    } else if (v.is_array()) {
      shown = "[";
      for (size_t k = 0; k < v.size(); ++k) {
        char text[32];
        std::snprintf(text, sizeof text, "%.7g", v[k].get<double>());
        shown += (k ? ", " : "") + std::string(text);
      }
      shown += "]";
    }
    out.push_back({s.name, type_of(s), range_of(s), shown, s.meaning});
  }
  return out;
}

std::vector<std::pair<std::string, std::string>> old_setting_names() {
  std::vector<std::pair<std::string, std::string>> out;
  for (const settings::Alias& a : settings::aliases()) out.emplace_back(a.old_name, a.name);
  return out;
}

}  // namespace desplat
