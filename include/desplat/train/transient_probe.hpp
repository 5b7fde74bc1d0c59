// --effects auto's test for transients (docs/METHOD.md §10, transients): does any training
// photo hold something the others do not? Colours along SfM tracks cannot tell (they differ as
// much on clean captures), so auto asks a short static-only model instead. A static
// model fits what the views agree on; a transient shows as a compact area that one view leaves
// unexplained while its neighbouring views explain the same surface points. Fitting error that
// is not transient (fine texture, view-dependent shine) shows in the neighbours at the same
// surface points too, and is not counted.
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

struct TransientRules {
  // The probe: a static-only model (the run's other settings, distractors off) trained for this
  // many steps at 1/factor of the training resolution, then judged at that resolution; the factor
  // is the largest power of two up to max_probe_factor that leaves the first training view's
  // short side at least min_probe_side pixels (below that, min_area is a few pixels and
  // misfit alone fills it).
  int probe_steps = 1000;
  int max_probe_factor = 4;
  int min_probe_side = 60;
  // A pixel is unexplained when mean |render − photo| over RGB reaches this (the tolerance of
  // the distractor growth rules, ResidualPenalties::tolerance) …
  float tolerance = 0.1f;
  // … and view-specific when, in addition, the median of that error over the neighbouring views
  // that see the same surface point (their depth there agrees, depth_tolerance) is at most half
  // the tolerance: they explain it.
  float neighbour_fraction = 0.5f;
  int neighbours = 6;             // the nearest camera centres …
  float max_axis_angle_deg = 60;  // … among views whose optical axis is this close
  float depth_tolerance =
      0.1f;  // the same surface there: its depth within this fraction of the neighbour's rendered depth
  // A connected area (4-neighbours) of view-specific pixels counts when it covers at least this
  // share of the frame: an object, not scattered misfit pixels.
  float min_area = 0.005f;
  // A view holds a transient when its counted areas cover at least this share of the frame;
  // the scene has transients when at least min_views_share of its views (and at least 2) do.
  // 3 %: on clean captures the probe's own misfit passes the neighbour test in areas just below
  // that share of a view, and real transients cover many views above it (docs/METHOD.md §10).
  float view_share = 0.03f;
  float min_views_share = 0.05f;
};

// One training view at the probe's resolution. Rows of `camera.width` pixels.
struct ProbeView {
  Camera camera;
  std::vector<float> error;  // [H·W] mean |render − photo| over RGB; < 0 where not judged (a user mask)
  std::vector<float>
      depth;  // [H·W] the render's depth along the optical axis [world units, normalized frame]; 0: no surface
};

struct TransientEvidence {
  std::vector<float> view_share;  // per view: the share of its frame in counted areas
  int views_with_transients = 0;
  int judged_views = 0;  // views with at least 2 neighbours
  bool transients = false;
  std::string reason;  // one sentence
};

// Judges probe views (all the same scene's training views at one resolution). Throws
// std::invalid_argument when a view's maps do not match its camera.
TransientEvidence judge_transients(const std::vector<ProbeView>& views, const TransientRules& rules = {});

// The probe's resolution factor for views of this size (rules above).
int probe_factor(int width, int height, const TransientRules& rules = {});

// Training view v of a trained probe at 1/factor resolution: its error against the photo,
// rendered in the view's own trained look (Trainer::training_look), and its depth.
ProbeView probe_view(const Trainer& probe, size_t v, int factor);

// Trains the probe on `data` with `config` (distractors turned off, rules.probe_steps steps, all at
// 1/probe_factor resolution), renders every training view in its own look, and judges them.
// Returns nullopt, having trained less, as soon as `stop` (when given) is set: a Ctrl-C.
// With `comm` of several ranks the probe is a job of those ranks (Trainer), stopped when any
// rank's `stop` is set, and every rank returns the same evidence.
std::optional<TransientEvidence> probe_transients(const TrainingData& data, TrainConfig config,
                                                  const TransientRules& rules = {},
                                                  const std::atomic<bool>* stop = nullptr,
                                                  Communicator* comm = nullptr);

}  // namespace desplat
