// The presets of desplat_train (docs/METHOD.md §7, presets).
#include "desplat/train/presets.hpp"

#include <stdexcept>

namespace desplat {

std::vector<std::string> preset_names() { return {"default", "paper"}; }

TrainConfig preset_config(std::string_view name) {
  TrainConfig c;
  if (name == "default") return c;
  if (name == "paper") {
    c.densify.stats.normalize_each_step = false;
    c.densify.stats.visible_count_from_one = true;
    c.densify.stats.radius_from_eigenvalue = true;
    c.densify.split_screen_needs_grad = false;
    c.densify.inherit_moments = false;
    c.distractors.reference_pixels = 0;  // K = initial_count = 1,000 per view
    c.distractors.lambda_explained = 0.0f;
    c.distractors.lambda_mask_tv = 0.0f;
    c.distractors.pixels_per_distractor = 0;
    c.distractors.reseed_starved_views = false;
    c.distractors.seed_uncovered = false;
    c.distractors.grow_after = 0;
    c.transient_points.action = TransientPointAction::keep;
    c.appearance.hidden_width = 128;  // the paper's appendix (WildGaussians' MLP)
    c.background.lambda_opaque = 0.0f;  // the authors' L_bg alone (docs/METHOD.md §11)
    return c;
  }
  std::string known;
  for (const std::string& n : preset_names()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown preset '" + std::string(name) + "' (known: " + known + ")");
}

}  // namespace desplat
