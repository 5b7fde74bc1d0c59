// DeSplat's per-view distractor Gaussians (docs/METHOD.md §5–7): every training view owns a
// small set of Gaussians with plain RGB colors that only that view renders and updates.
// They live in the normalized world frame like the static Gaussians; at initialization
// they sit on a small plane just in front of their camera.
#pragma once

#include <cstdint>

#include "desplat/core/camera.hpp"
#include "desplat/train/density.hpp"
#include "desplat/core/gaussians.hpp"
#include "desplat/train/trainable.hpp"

namespace desplat {

struct DistractorSettings {
  bool enabled = true;          // false: the static-only baseline (Splatfacto)
  // K per training view (§5): initial_count distractors for an image of reference_pixels
  // pixels (the paper's 504×378, RobustNeRF at 1/8), scaled with each view's pixel count
  // so the distractors cover the image as densely as the authors'. Their capacity is per
  // image: 1,000 on a 64×117 view is one per 7 pixels, enough to memorize it and take the
  // static scene away (README, "Distractor density"). reference_pixels = 0: K = initial_count.
  int initial_count = 1000;
  int reference_pixels = 504 * 378;
  float init_depth = 0.02f;     // ρ: the plane's depth in camera coordinates [normalized units]
  float init_half_width = 0.01f;// x, y ~ U(−w, w) on that plane [normalized units]
  float init_opacity = 0.1f;
  // Rates of §6; colors_dc is the RGB rate (colors_rest is unused in RGB mode). The
  // means' rate decays with the same schedule as the static means'.
  LearningRates lr{1.6e-4f, 5e-2f, 1e-2f, 5e-2f, 2.5e-2f, 0.0f};
  bool density_control = true;  // per-view split/duplicate/cull (§7); false: never refined
  int refine_every_epochs = 10; // refine every view each time all views were seen this many more times
  bool regularize = true;       // the two opacity regularizers of §4
  float lambda_static = 0.01f;  // weight of mean(1 − A_s)
  float lambda_distractor = 0.01f;  // weight of mean(A_d)
};

// K for a view of this camera's size: initial_count scaled by pixels / reference_pixels
// (rounded, at least 1 unless initial_count is 0), or initial_count when reference_pixels is 0.
int distractor_count_for(const Camera& camera, const DistractorSettings& settings);

// distractor_count_for(camera) distractors for one view (§5): camera coordinates
// x, y ~ U(−w, w), z = ρ, mapped to the world with the view's pose; log-scale = log(mean
// distance to the 3 nearest others in the set); uniformly random unit quaternion; the initial opacity; RGB ~ U(0, 1).
// Deterministic for a seed. Returns ColorMode::RGB Gaussians.
GaussianSet init_distractors(const Camera& camera, const DistractorSettings& settings, uint64_t seed);

// Whether the per-view distractor refinement runs after step `step` (counting from 0):
// at the static refinement cadence (after the warm-up, every refine_every steps), the
// first such step each time all views have been seen refine_every_epochs more times,
// i.e. step mod (refine_every_epochs · #views) < refine_every.
bool distractor_refine_due(int64_t step, int num_train_views, const DensifySettings& densify,
                           const DistractorSettings& settings);

// One view's refinement (§7): the static thresholds on the view's own statistics, split /
// duplicate until densify.stop_split_at, culling always, including every distractor the
// view did not see since the last refinement. No opacity reset.
RefineReport refine_distractors(TrainableGaussians& view_distractors, const DensifySettings& densify, int64_t step,
                                int image_size, std::mt19937_64& rng);

}  // namespace desplat
