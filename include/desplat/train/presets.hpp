// Named starting configurations for desplat_train --preset (docs/METHOD.md §7, presets):
//   "fast"     a 3,000-step preview: the default's schedule (resolution, SH, position decay,
//              densification, opacity resets, distractor refinement) fitted into 3,000 steps;
//   "default"  TrainConfig{}: the project's defaults (docs/METHOD.md §7, docs/CONFIG.md);
//   "paper"    the authors' code's behaviour, for reproducing the paper: their densification
//              statistics and split rule, 1,000 distractors per view whatever the image
//              size, and none of our distractor growth rules.
// --config is applied on top of the preset (jobs/run_settings.hpp gives the whole order).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "desplat/train/train_config.hpp"

namespace desplat {

std::vector<std::string> preset_names();
// Throws std::invalid_argument naming the preset and the known ones.
TrainConfig preset_config(std::string_view name);

}  // namespace desplat
