#include "desplat/train/effects.hpp"

#include <sstream>
#include <stdexcept>

namespace desplat {

Effects Effects::parse(const std::string& text) {
  Effects e;
  if (text == "none") return e;
  std::stringstream list(text);
  std::string name;
  bool any = false;
  while (std::getline(list, name, ',')) {
    if (name == "distractors") {
      e.distractors = true;
    } else if (name == "appearance") {
      e.appearance = true;
    } else if (name == "auto" || name == "background") {
      throw std::invalid_argument("--effects: '" + name + "' is not available yet; name the effects to model " +
                                  "(none, or a list of distractors, appearance)");
    } else {
      throw std::invalid_argument("--effects: unknown effect '" + name +
                                  "' (none, or a comma-separated list of distractors, appearance)");
    }
    any = true;
  }
  if (!any) throw std::invalid_argument("--effects is empty (none, or a comma-separated list of distractors, appearance)");
  return e;
}

Effects Effects::of(const TrainConfig& config) { return {config.distractors.enabled, config.appearance.enabled}; }

void Effects::apply(TrainConfig& config) const {
  config.distractors.enabled = distractors;
  config.appearance.enabled = appearance;
}

std::string Effects::to_string() const {
  std::string out;
  for (auto [on, name] : {std::pair{distractors, "distractors"}, std::pair{appearance, "appearance"}})
    if (on) out += (out.empty() ? "" : ",") + std::string(name);
  return out.empty() ? "none" : out;
}

}  // namespace desplat
