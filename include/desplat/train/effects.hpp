// Which effects a model represents beyond the static scene (docs/METHOD.md §10):
// `--effects none | distractors,appearance,…`. Each effect is one switch of TrainConfig;
// this is the one place that maps names to switches.
#pragma once

#include <string>

#include "desplat/train/trainer.hpp"

namespace desplat {

struct Effects {
  bool distractors = false;  // per-view distractor Gaussians (DeSplat's decomposition)
  bool appearance = false;   // per-image appearance embeddings and MLP (static colours)

  // "none" or a comma-separated list of "distractors" and "appearance", in any order. Throws
  // std::invalid_argument naming the unknown or unavailable entry ("auto" and "background"
  // are not available yet and say so).
  static Effects parse(const std::string& text);
  static Effects of(const TrainConfig& config);
  void apply(TrainConfig& config) const;
  std::string to_string() const;  // "none" or the list, in the order above
};

}  // namespace desplat
