// Which effects a model represents beyond the static scene (docs/METHOD.md §10):
// `--effects none | distractors,appearance,…`. Each effect is one switch of TrainConfig;
// this is the one place that maps names to switches.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "desplat/comm/communicator.hpp"
#include "desplat/train/train_config.hpp"
#include "desplat/train/training_data.hpp"

namespace desplat {

struct Effects {
  bool distractors = false;  // per-view distractor Gaussians (DeSplat's decomposition)
  bool appearance = false;   // per-image appearance embeddings and MLP (static colours)
  bool background = false;   // per-image background model behind both layers (sky)

  // "none" or a comma-separated list of "distractors", "appearance" and "background", in any
  // order. Throws std::invalid_argument naming the unknown entry ("auto" is the caller's:
  // choose_effects below).
  static Effects parse(const std::string& text);
  static Effects of(const TrainConfig& config);
  void apply(TrainConfig& config) const;
  std::string to_string() const;  // "none" or the list, in the order above
};

// --effects auto (docs/METHOD.md §10, choosing the effects): evidence gathered before training
// from the SfM tracks. Every track element of a training view is a sample: the photo's colour
// at the point's projection against the point's own colour (COLMAP's mean over its track).
// The appearance and background models are decided from this evidence, and only ever turned on.
// Transients are not (colours along tracks do not tell them apart, docs/METHOD.md §10):
// transient_probe.hpp decides distractors, and jobs/run_settings.hpp is where the choices are
// made for a run.
struct EffectsRules {
  // Appearance when the views' brightness gains (the median log₂ ratio of their samples, mean
  // over RGB) spread by more than this many stops (robust standard deviation over views), or
  // their colour balance (each channel's gain minus the view's mean gain) by more than
  // white_balance_spread (log₂ units, robust standard deviation over views, the largest of
  // the three channels).
  float exposure_spread_stops = 0.2f;
  float white_balance_spread = 0.05f;
  int min_samples_per_view = 30;  // fewer: the view gives no evidence
  // Background when, in the median judged view, the cells of a sky_grid-wide grid that hold no
  // SfM sample, are smooth (mean |Laplacian| of 4×4-pixel luminance means ≤ sky_smooth_ratio ×
  // the median of the view's cells that hold samples) and connect to the frame's top edge through such cells
  // cover more than sky_share of the frame: a featureless region above the scene that no
  // surface explains is sky (or something as far and as plain), which only the background
  // model can represent.
  float sky_share = 0.1f;
  int sky_grid = 16;
  float sky_smooth_ratio = 0.25f;
};

struct ViewEvidence {
  std::string name;
  int samples = 0;
  std::array<float, 3> log2_gain{0, 0, 0};  // per channel, the median log₂(photo / point colour)
  float open_top_share = 0;                 // share of the frame in sky-like grid cells connected to the top edge
  bool gain_judged = false;                 // every channel had min_samples_per_view usable samples
};

struct EffectsEvidence {
  std::vector<ViewEvidence> views;  // data.train order
  int judged_views = 0;             // views with at least min_samples_per_view samples
  double exposure_spread_stops = 0, white_balance_spread = 0;
  bool appearance = false;        // the evidence calls for the appearance model
  std::string reason;             // one sentence: why appearance is called for or not
  double open_top_share = 0;      // median over judged views
  bool background = false;        // the evidence calls for the background model
  std::string background_reason;  // one sentence: why the background model is called for or not
};

// Throws std::invalid_argument when the track information does not match the points.
// In a job of several ranks (`comm`, collective) each view is judged on the rank holding its
// photo (rank_of_view) and every rank returns the whole evidence.
EffectsEvidence examine_effects(const TrainingData& data, const EffectsRules& rules = {}, Communicator* comm = nullptr);

// Each training view's colour gain against the SfM point colours, per channel (data.train
// order): 2^log2_gain where the view's gain is judged (ViewEvidence::gain_judged), else 1 (no
// evidence). A point of colour c looks like min(1, gain · c) in that view.
std::vector<std::array<float, 3>> view_gains(const TrainingData& data, const EffectsRules& rules = {},
                                             Communicator* comm = nullptr);

// --effects auto, appearance and background: `configured` (the preset's and --config's set) plus
// appearance and background when `evidence` calls for them; a line of `why` for each says why it
// is on or off. Distractors are left as configured: the caller decides them with the transient
// probe (transient_probe.hpp), which needs the other two settled.
Effects choose_effects(const Effects& configured, const EffectsEvidence& evidence, std::vector<std::string>& why);

}  // namespace desplat
