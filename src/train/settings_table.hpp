// The settings table: every TrainConfig setting once, with its name in config.json, its
// range and its meaning. Validation, JSON reading and writing, the resume comparison, the
// "absent from an older config.json" list and docs/CONFIG.md all iterate this table, so a
// new setting is one entry here (plus its field in TrainConfig, whose initializer is the
// default).
#pragma once

#include <array>
#include <cstdint>
#include <variant>
#include <vector>

#include "desplat/train/train_config.hpp"

namespace desplat::settings {

using Field =
    std::variant<int*, int64_t*, float*, bool*, uint64_t*, std::array<float, 3>*, TransientPointAction*, KernelIsa*>;

// A numeric setting's allowed values: [lo, hi], with either end open. Integer settings are
// also capped at their type's largest value. `note` says what a special value means.
struct Bounds {
  double lo = 0, hi = 0;
  bool lo_open = false, hi_open = false;
  const char* note = nullptr;
};

struct Setting {
  const char* name;     // config.json path, dots between levels: "densify.refine_every"
  Field field;          // the member of the TrainConfig the table was built for
  Bounds bounds;        // numbers and each of eval_background's values; unused otherwise
  const char* meaning;  // one sentence
};

// The table bound to `c`'s members, in config.json's order.
std::vector<Setting> table(TrainConfig& c);

// Names earlier config.json files used, read as today's: {old, new}.
struct Alias {
  const char* old_name;
  const char* name;
};
const std::vector<Alias>& aliases();

}  // namespace desplat::settings
