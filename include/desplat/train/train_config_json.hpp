// TrainConfig ⇄ JSON (config.json's "train" part and desplat_train --config). Every setting's
// name, range and meaning is one entry of the settings table (src/train/settings_table.cpp);
// docs/CONFIG.md is generated from it (settings_reference_markdown).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/train/train_config.hpp"

namespace desplat {

nlohmann::json config_to_json(const TrainConfig& c);
// Overrides the settings present in `j` on top of `base`, then validate_config. Rejects unknown
// keys, wrongly typed values and values out of range (checked as written, so 1.7 for an
// integer or 1e20 for a 32-bit count is named as given) with the setting's name and range in
// the message. Reads the old names of old_setting_names as today's.
TrainConfig config_from_json(const nlohmann::json& j, TrainConfig base = {});

// The settings (names as in the JSON, e.g. "densify.camera_path_radius") whose values differ
// between `a` and `b`, each as "<setting> <a's value> (<b's value> in <b_name>)", in the
// table's order; settings named in `ignore` are left out.
std::vector<std::string> config_differences(const TrainConfig& a, const TrainConfig& b, const std::string& b_name,
                                            const std::vector<std::string>& ignore = {});

// The settings (names as in the JSON) that `j` does not hold, in the table's order: reading
// `j` gives them their defaults (a config.json written before they existed).
std::vector<std::string> settings_absent_from(const nlohmann::json& j);

// Throws std::invalid_argument "config: <setting> must be <what is allowed> (got <value>)"
// for the first setting out of its range (the table's), or for a kernel_isa this CPU lacks.
void validate_config(const TrainConfig& c);

// One row of the configuration reference: the setting's JSON name, its type ("integer",
// "number", "boolean", …), what it allows, its default and a one-sentence meaning.
struct SettingDescription {
  std::string name, type, range, default_value, meaning;
};
std::vector<SettingDescription> describe_settings();
// {old name, today's name} of settings renamed since earlier config.json files.
std::vector<std::pair<std::string, std::string>> old_setting_names();
// docs/CONFIG.md: describe_settings as markdown tables, one per name prefix.
std::string settings_reference_markdown();

}  // namespace desplat
