// TrainConfig ⇄ JSON. Every field has a name; the defaults are docs/METHOD.md's. Reading
// rejects unknown keys and wrongly typed values with the key's path in the message.
#pragma once

#include <nlohmann/json.hpp>

#include "desplat/train/trainer.hpp"

namespace desplat {

nlohmann::json config_to_json(const TrainConfig& c);
// Overrides the fields present in `j` on top of `base`, then validate_config.
TrainConfig config_from_json(const nlohmann::json& j, TrainConfig base = {});

// Throws std::invalid_argument "config: <setting> must be <what is allowed> (got <value>)"
// for the first setting out of its range: counts and intervals that would divide by zero,
// rates that would make the run useless, NaN/Inf anywhere.
void validate_config(const TrainConfig& c);

}  // namespace desplat
