// DeSplat's per-view distractor Gaussians (docs/METHOD.md §5–7): every training view owns a
// small set of Gaussians with plain RGB colors that only that view renders and updates.
// They live in the normalized world frame like the static Gaussians; at initialization
// they sit on a small plane just in front of their camera.
#pragma once

#include <cstdint>
#include <span>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"
#include "desplat/train/density.hpp"
#include "desplat/train/trainable.hpp"

namespace desplat {

struct DistractorSettings {
  bool enabled = true;  // false: the static-only baseline (Splatfacto)
  // K per training view (§5): initial_count distractors for an image of reference_pixels
  // pixels (the paper's 504×378, RobustNeRF at 1/8), scaled with each view's pixel count
  // so the distractors cover the image as densely as the authors'. Their capacity is per
  // image: 1,000 on a 64×117 view is one per 7 pixels, enough to memorize it and take the
  // static scene away (docs/METHOD.md §5). reference_pixels = 0: K = initial_count.
  int initial_count = 1000;
  int reference_pixels = 504 * 378;
  float init_depth = 0.02f;       // ρ: the plane's depth in camera coordinates [normalized units]
  float init_half_width = 0.01f;  // x, y ~ U(−w, w) on that plane [normalized units]
  float init_opacity = 0.1f;
  // Rates of §6; colors_dc is the RGB rate (colors_rest is unused in RGB mode). The
  // means' rate decays with the same schedule as the static means'.
  LearningRates lr{.means = 1.6e-4f,
                   .log_scales = 5e-2f,
                   .quats = 1e-2f,
                   .opacity_logits = 5e-2f,
                   .colors_dc = 2.5e-2f,
                   .colors_rest = 0.0f};
  bool density_control = true;  // per-view split/duplicate/cull (§7); false: never refined
  // Refine every view each time all views were seen this many more times. 3, not the
  // authors' 10 (--preset paper): at 10 a buffer first grows after 10 visits, while the static
  // layer takes on the occluders' colours (docs/METHOD.md §7; docs/BENCHMARKS.md, the defaults).
  int refine_every_epochs = 3;
  bool regularize = true;           // the two opacity regularizers of §4
  float lambda_static = 0.01f;      // weight of mean(1 − A_s)
  float lambda_distractor = 0.01f;  // weight of mean(A_d)
  // Weight of the distractor mask's total variation (train/mask_coherence.hpp; ours): a
  // transient object is one connected area, also where it matches the scene behind it.
  // Counted only with `regularize`; 0 (off) in --preset paper (docs/METHOD.md §7).
  float lambda_mask_tv = 0.1f;
  // Weight of the occluder-colour prior (train/mask_coherence.hpp; ours): a transient object is
  // opaque and shows the photo's colour. Counted only with `regularize`, from step owned_after
  // on, as the owned pull (from step 0 it competes with the static layer's first fit); 0 (off)
  // in --preset paper. 0.4 is half the L1 term's weight (1 − ssim_lambda), so fitting the
  // photo always outweighs the prior (docs/METHOD.md §7).
  float lambda_occluder_colour = 0.4f;

  // Growth control (docs/METHOD.md §7, growth control); each rule is off at 0 / false, as in
  // the authors' code (--preset paper). The defaults' reasons: docs/METHOD.md §7.
  // A pixel is "explained" by a render when its mean |render − target| over RGB is below
  // explained_tolerance (in [0, 1] colour units).
  float explained_tolerance = 0.1f;
  // Weight of mean(A_d · [the static layer alone explains the pixel]): a distractor over a
  // pixel the static scene already explains can only be memorizing static detail.
  float lambda_explained = 0.05f;
  // Weight of mean((1 − A_d) · owned), owned = the static layer misses the pixel and its 8
  // neighbours, the composite explains it: there the distractor layer is the explanation, and
  // a transient object is opaque. Without it A_d stops at the least alpha that fits the colour
  // and masks stay partial (docs/METHOD.md §7). From step owned_after on: the static layer
  // first gets its chance at what few views see.
  float lambda_owned = 0.2f;
  int owned_after = 3000;  // also when the occluder-colour prior starts
  // Growth cap: a refinement grows a view's buffer to at most (pixels the static layer left
  // unexplained in the view's latest step, as count_connected_misses counts them, at full
  // training resolution) /
  // pixels_per_distractor, the highest gradients first. 0: unlimited. 6: once the summed-alpha
  // limit and the opaque-pulling rules keep distractors from stacking, fewer than one per 4
  // pixels fit real occluders as well, and one per 8 is too few (docs/METHOD.md §7).
  int pixels_per_distractor = 6;
  // What the cap, the starved test and the uncovered seeding count as the static layer's
  // unexplained pixels. false: every miss. true: only misses inside a connected area (the
  // 3×3 opening of the miss mask, ViewResidual::static_unexplained_in_areas), on the idea
  // that thin and isolated misses are fitting error on edges and fine texture. Off by default:
  // it helped a clutter-free synthetic scene and hurt the clean fox (docs/BENCHMARKS.md,
  // the defaults).
  bool count_connected_misses = false;
  // Split or duplicate by the angle a distractor subtends, as the static layer is judged at
  // the scene's depth: densify.size_threshold is a world size for Gaussians near the scene's
  // median depth D, so a distractor (at depth init_depth ρ, about 1/65 of D) is large above
  // size_threshold · ρ / D. With the world threshold no distractor is ever large (their
  // scales are two orders of magnitude below the threshold): every high-gradient one is
  // duplicated at full size. Off by default: it saves work but loses quality on the occluded
  // fox (docs/BENCHMARKS.md, the defaults). Needs sparse points (D); the world threshold
  // without them.
  bool size_threshold_at_scene_depth = false;
  // A view whose buffer has fewer than one distractor per 256 pixels the static layer leaves
  // unexplained (and > 1 % of the frame unexplained) is re-seeded at those pixels.
  bool reseed_starved_views = true;
  // A view whose composite leaves over 1 % of its pixels unexplained and that has room under
  // its cap is seeded where neither layer explains the pixel (interiors of such regions only, see erode_mask):
  // densification grows distractors only where some already are, so an occluder no distractor reaches would otherwise
  // stay unexplained, and the static layer would fit it.
  bool seed_uncovered = true;
  // Seeding (the starved and uncovered rules) waits for step seed_after, the first
  // resolution switch: before it the static layer still misses detail everywhere, and a seed
  // there takes a region the static layer would have fitted. 0: from the warm-up on (--preset
  // fast and paper).
  int seed_after = 3000;
  // Seeding also waits one refinement period after a static opacity reset, as after a
  // resolution switch: right after it the static layer is partly transparent everywhere.
  bool seed_waits_after_reset = true;
  // Distractor densification starts after this step (culling runs from the warm-up on), so
  // the static layer has had its chance at content few views see.
  int grow_after = 0;
  // Idle cull: at each refinement, before growth, a distractor whose blend weight in its
  // view (Σ over pixels of α·T, blend_weights) is below this many pixels of the view at full
  // training resolution is culled. Such a distractor changes its photo's render by less than
  // this many pixels' worth of colour: hidden behind other distractors, nearly transparent or
  // off screen, it costs time and keeps the cap's room from Gaussians that are needed.
  // 0: off, the default: it helps the occluded fox's masks but loses quality on the clutter
  // benchmark (docs/BENCHMARKS.md, the defaults).
  float min_blend_weight = 0.0f;
  // Summed-alpha limit on densification (docs/METHOD.md §7): a refinement duplicates or
  // splits a view's distractors only while their alpha summed over the image
  // (distractor_alpha_sum, at full training resolution) is below max_alpha_sum × the pixels
  // the static layer leaves unexplained, and adds at most as many as fill the rest at the
  // buffer's mean alpha per distractor. Layers whose α sum to s over a pixel leave it a
  // transmittance ≤ e^(−s): at ln 10 ≈ 2.3 it is ≥ 90 % covered, and past that a copy adds a
  // layer, not coverage. Seeding (the starved and uncovered rules) is not limited: it goes
  // where no distractor covers. 0: off (--preset paper).
  float max_alpha_sum = 2.3f;
};

// K for a view of this camera's size: initial_count scaled by pixels / reference_pixels
// (rounded, at least 1 unless initial_count is 0), or initial_count when reference_pixels is 0.
int distractor_count_for(const Camera& camera, const DistractorSettings& settings);

// Refuses (std::invalid_argument, naming the setting, the view and the figure) initial distractor
// counts a run cannot use: more than a view's pixels (a distractor explains at least a pixel, so
// more add nothing but memory and time), or more distractor memory, over all `cameras`, than
// the machine has (kDistractorBytes per Gaussian against the physical memory).
void check_initial_distractors(const std::vector<Camera>& cameras, const DistractorSettings& settings);
// Bytes one distractor Gaussian takes while training: its 14 RGB-mode floats with both Adam
// moments and a gradient, its densification statistics, and the initialization's temporaries.
inline constexpr double kDistractorBytes = 256;

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

// The world-size threshold refine_distractors splits above: densify.size_threshold, scaled by
// init_depth / scene_depth with size_threshold_at_scene_depth (scene_depth > 0 only; [world units]).
float distractor_size_threshold(const DensifySettings& densify, const DistractorSettings& settings, double scene_depth);

// One view's refinement (§7): the static thresholds on the view's own statistics (large:
// above distractor_size_threshold), split / duplicate until densify.stop_split_at, culling
// always, including every distractor the view did not see since the last refinement. No
// opacity reset.
// `max_new`: the view's growth budget (kUnlimitedGrowth: none).
// `scene_depth`: the median scene depth (median_scene_depth, [world units]; 0: unknown).
RefineReport refine_distractors(TrainableGaussians& view_distractors, const DensifySettings& densify,
                                const DistractorSettings& settings, int64_t step, int image_size, std::mt19937_64& rng,
                                int64_t max_new = kUnlimitedGrowth, double scene_depth = 0.0);

// The idle cull (DistractorSettings::min_blend_weight): renders `view_distractors` with
// `camera` (the view at the step's training size, `factor` times smaller than full training
// resolution per axis) and removes every distractor whose blend weight, times factor², is
// below min_blend_weight. Returns how many were removed; nothing when the setting is 0.
int64_t cull_idle_distractors(TrainableGaussians& view_distractors, const Camera& camera, int factor,
                              const DistractorSettings& settings);

// Σ over the distractors visible from `camera` of their alpha integrated over the image plane,
// o·2π·√det Σ₂ (Σ₂ the projected covariance) [pixels of `camera`]: the buffer's summed alpha
// over all its layers. A Gaussian's integral is counted whole (at most the image's pixels),
// also the part of it off screen.
double distractor_alpha_sum(const GaussianView& view_distractors, const Camera& camera);

// How many distractors densification may add under max_alpha_sum: kUnlimitedGrowth when the
// setting is 0 or the buffer is empty or has no alpha; 0 when alpha_sum ≥ max_alpha_sum ·
// (static_unexplained_fraction · pixels); else ⌊(that limit − alpha_sum) / (alpha_sum /
// buffer_size)⌋. `pixels` and `alpha_sum` are at full training resolution.
int64_t alpha_sum_budget(size_t buffer_size, double alpha_sum, double static_unexplained_fraction, int64_t pixels,
                         const DistractorSettings& settings);

// A view's distractor cap: static_unexplained_fraction · pixels / pixels_per_distractor
// (rounded down; the fraction clamped to [0, 1]), with `pixels` = W·H of the view at full
// training resolution. kUnlimitedGrowth when pixels_per_distractor is 0.
int64_t distractor_cap(double static_unexplained_fraction, int64_t pixels, const DistractorSettings& settings);
// How many Gaussians a refinement may add to a buffer of `buffer_size`: max(0, cap − size),
// or kUnlimitedGrowth.
int64_t distractor_growth_budget(size_t buffer_size, double static_unexplained_fraction, int64_t pixels,
                                 const DistractorSettings& settings);

// Whether a view's buffer is starved (reseed_starved_views): more than 1 % of its pixels
// unexplained by the static layer and fewer than one distractor per 256 of them.
bool distractor_buffer_starved(size_t buffer_size, double static_unexplained_fraction, int64_t pixels);

// How many distractors seed_uncovered adds to a buffer of `buffer_size`: when the composite
// leaves over 1 % of the view unexplained, one per pixels_per_distractor (4 when that is 0)
// such pixels, counted at full training resolution (`pixels`), at most the cap's room
// (distractor_growth_budget); else 0.
int64_t uncovered_seed_count(size_t buffer_size, double static_unexplained_fraction,
                             double composite_unexplained_fraction, int64_t pixels, const DistractorSettings& settings);

// `count` new distractors for a starved or uncovered view, one per pixel drawn (without replacement,
// in random order) from `mask` ([H·W] of `camera`, nonzero = unexplained), placed on the
// initialization plane (depth init_depth) along that pixel's ray, with the target's colour
// there (`target` [H·W·3]), the initial opacity, and a footprint of about
// √pixels_per_distractor pixels (2 when that is 0). Deterministic for a seed.
GaussianSet reseed_distractors(const Camera& camera, std::span<const uint8_t> mask, std::span<const float> target,
                               size_t count, const DistractorSettings& settings, uint64_t seed);

}  // namespace desplat
