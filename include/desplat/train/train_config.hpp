// A training run's configuration: every setting of the Trainer, with its default as the
// member's initializer. The settings' names in config.json, their ranges and meanings are
// the settings table's (src/train/settings_table.cpp, docs/CONFIG.md); a new setting is a
// member here plus one entry there.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

#include "desplat/raster/raster.hpp"
#include "desplat/train/appearance.hpp"
#include "desplat/train/background.hpp"
#include "desplat/train/density.hpp"
#include "desplat/train/distractors.hpp"
#include "desplat/train/param_groups.hpp"
#include "desplat/train/transient_points.hpp"

namespace desplat {

struct TrainConfig {
  // Views seen over the run: every schedule below (SH degree, resolution, the means' decay,
  // density control, distractor refinement) counts views, whatever `batch` is.
  int64_t iterations = 30000;
  // Training views rendered per optimizer step (docs/METHOD.md §6, batches): their static
  // gradients and densification statistics are summed into one Adam step (rates × √batch,
  // betas ^ batch); distractors, appearance and background keep one update per view. 1: one
  // view per step.
  int batch = 1;
  int sh_degree = 3;
  int sh_degree_interval = 1000;   // active SH degree +1 every this many steps
  int num_downscales = 2;          // train at 2^num_downscales lower resolution first …
  int resolution_schedule = 3000;  // … halving the factor every this many steps
  float ssim_lambda = 0.2f;
  float means_lr_final = 1.6e-6f;        // means' rate decays exponentially to this …
  int64_t means_lr_decay_steps = 30000;  // … over this many steps, whatever `iterations` is (Splatfacto)
  LearningRates lr;
  DensifySettings densify;
  DistractorSettings distractors;
  TransientPointSettings transient_points;  // what initialization does with transient sparse points
  AppearanceSettings appearance;            // per-image appearance of the static layer (off: plain colours)
  // The learned background behind both layers (background.hpp); when on it replaces the
  // random training background and the static opacity regularizer λ_s (L_bg takes its place).
  BackgroundSettings background;
  // true: Adam updates only the Gaussians the step's view sees (their parameters and
  // moments); one outside the view keeps them unchanged (docs/METHOD.md §6). false (the
  // default and the authors'): every Gaussian every step.
  bool selective_adam = false;
  // The rasterizer's pixel-loop instruction set (raster.hpp); auto: the widest this CPU has.
  // The paths differ only in float rounding (docs/METHOD.md §3).
  KernelIsa kernel_isa = KernelIsa::Auto;
  bool random_background = true;
  std::array<float, 3> eval_background{0.1490f, 0.1647f, 0.2157f};
  int random_init_points = 50000;   // used when the scene has no points
  float random_init_extent = 1.0f;  // half-width of the cube for random initialization
  uint64_t seed = 0;
  // 0: all cores. > 0 also becomes the calling thread's OpenMP default team size, so the
  // optimizer, loss and initialization honour it as the rasterizer does.
  int threads = 0;

  // The resolution schedule, in one place: the factor step `step` trains at (1 = full
  // training resolution), and the first step that trains at full resolution.
  int downscale_at(int64_t step) const {
    return 1 << std::max<int64_t>(num_downscales - step / resolution_schedule, 0);
  }
  int64_t full_resolution_from() const { return int64_t(num_downscales) * resolution_schedule; }
  // The SH degree step `step` renders and trains with (one band more every
  // sh_degree_interval steps); a finished model renders with the degree it ended at.
  int sh_degree_at(int64_t step) const {
    return static_cast<int>(std::min<int64_t>(step / sh_degree_interval, sh_degree));
  }
};

}  // namespace desplat
