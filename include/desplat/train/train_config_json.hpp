// TrainConfig ⇄ JSON. Every field has a name; the defaults are docs/METHOD.md's. Reading
// rejects unknown keys and wrongly typed values with the key's path in the message.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/train/trainer.hpp"

namespace desplat {

nlohmann::json config_to_json(const TrainConfig& c);
// Overrides the fields present in `j` on top of `base`, then validate_config.
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
// for the first setting out of its range: counts and intervals that would divide by zero,
// rates that would make the run useless, NaN/Inf anywhere.
void validate_config(const TrainConfig& c);

}  // namespace desplat
