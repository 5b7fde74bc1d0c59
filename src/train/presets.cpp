// The presets of desplat_train (docs/METHOD.md §7, presets).
#include "desplat/train/presets.hpp"

#include <stdexcept>

namespace desplat {

std::vector<std::string> preset_names() { return {"fast", "default", "paper"}; }

TrainConfig preset_config(std::string_view name) {
  TrainConfig c;
  if (name == "default") return c;
  if (name == "fast") {
    // A 3,000-step preview (docs/METHOD.md §7, presets).
    c.iterations = 3000;
    c.resolution_schedule = 1000;           // a third of the run at each of 1/4, 1/2 and full resolution
    c.sh_degree_interval = 300;             // degree 3 by step 900, before full resolution, as the default by 3,000
    c.background.sh_degree_interval = 150;  // half the static interval, as in the default
    c.means_lr_decay_steps = 3000;          // positions settle by the end of this run, not of 30,000 steps
    c.densify.warmup = 200;
    c.densify.stop_split_at = 2500;        // the last 500 steps settle what densification added
    c.densify.stop_screen_size_at = 1000;  // the coarse third only, as the default's 4,000 ends early
    c.densify.reset_alpha_every = 10;      // opacity resets at steps 1,000 and 2,000 (30 would never fire)
    c.distractors.owned_after = 1000;      // after the coarse third, as the default after its first level
    // Seeding from the warm-up on: a run this short has no step to wait for.
    c.distractors.seed_after = 0;
    c.distractors.seed_waits_after_reset = false;
    return c;
  }
  if (name == "paper") {
    c.densify.stats.normalize_each_step = false;
    c.densify.stats.visible_count_from_one = true;
    c.densify.stats.radius_from_eigenvalue = true;
    c.densify.stats.hide_behind_distractors = false;
    c.densify.stats.gradient_per_seen_pixel = false;
    c.densify.split_screen_needs_grad = false;
    c.densify.inherit_moments = false;
    c.densify.camera_path.radius = 0.0f;     // no camera-path cull …
    c.densify.camera_path.blind_gap = 0.0f;  // … nor blind-gap cull
    c.distractors.reference_pixels = 0;      // K = initial_count = 1,000 per view
    c.distractors.lambda_explained = 0.0f;
    c.distractors.lambda_owned = 0.0f;
    c.distractors.refine_every_epochs = 10;
    c.distractors.lambda_mask_tv = 0.0f;
    c.distractors.lambda_occluder_colour = 0.0f;
    c.distractors.pixels_per_distractor = 0;
    c.distractors.size_threshold_at_scene_depth = false;  // the default too, stated for the record
    c.distractors.reseed_starved_views = false;
    c.distractors.seed_uncovered = false;
    c.distractors.grow_after = 0;
    c.distractors.seed_after = 0;  // seeding is off; stated for the record
    c.distractors.seed_waits_after_reset = false;
    c.distractors.min_blend_weight = 0.0f;  // no idle cull; the default too, stated for the record
    c.distractors.max_alpha_sum = 0.0f;     // copies whatever the buffer's summed alpha
    c.transient_points.action = TransientPointAction::keep;
    c.appearance.hidden_width = 128;  // the paper's appendix (WildGaussians' MLP)
    c.appearance.lr_image = 1e-3f;    // the appendix's rate for the image embeddings
    c.background.lr_image = 1e-3f;
    c.appearance.test_start_from_best_look = false;  // the test-time fit from the mean look, as before
    c.background.lambda_opaque = 0.0f;               // the authors' L_bg alone (docs/METHOD.md §11)
    return c;
  }
  std::string known;
  for (const std::string& n : preset_names()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown preset '" + std::string(name) + "' (known: " + known + ")");
}

}  // namespace desplat
