// TrainConfig ⇄ JSON. Every field has a name; the defaults are docs/METHOD.md's. Reading
// rejects unknown keys and wrongly typed values with the key's path in the message.
#pragma once

#include <nlohmann/json.hpp>

#include "desplat/train/trainer.hpp"

namespace desplat {

nlohmann::json config_to_json(const TrainConfig& c);
// Overrides the fields present in `j` on top of `base`.
TrainConfig config_from_json(const nlohmann::json& j, TrainConfig base = {});

}  // namespace desplat
