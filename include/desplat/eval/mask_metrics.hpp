// How well a trained DeSplat model's distractor masks (A_d > 0.5, docs/METHOD.md §8) match a
// scene's ground-truth distractor masks (masks.hpp), per training view and on average.
//
// Ownership and threads: plain values; evaluate_distractor_masks renders with the trainer's
// OpenMP settings and reads each mask file once.
#pragma once

#include <string>
#include <vector>

#include "desplat/io/masks.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

struct ViewMaskMetrics {
  std::string name;  // the training view's image name
  MaskScore score;
};

struct MaskMetrics {
  std::vector<ViewMaskMetrics> views;  // every training view that has a ground-truth mask
  // Mean IoU over views whose truth is non-empty (occluded views); 0 when there are none.
  double mean_iou = 0;
  int occluded_views = 0;
  // Mean predicted_fraction over views whose truth is empty: the false-positive area on clean views.
  double mean_clean_view_false_positive = 0;
  int clean_views = 0;
};

// Scores the distractor mask of each of trainer.data().train's views against the mask of the
// scene view with the same name. Views without a mask file are skipped; a trainer without
// distractors (static-only) predicts empty masks. Returns no views when the scene has no masks.
// `scene` must be the scene the trainer's data was loaded from (same downscale); a size
// mismatch throws std::invalid_argument naming the view.
MaskMetrics evaluate_distractor_masks(const Trainer& trainer, const Scene& scene);

}  // namespace desplat
