// Distractors: per-view objects between a training camera and the static scene. Each
// cluttered view gets its own random set (new positions, sizes, shapes and textures), the way
// objects and people differ from photo to photo in RobustNeRF / On-the-go captures.
#pragma once

#include <vector>

#include "desplat/io/colmap.hpp"
#include "synth/camera_path.hpp"
#include "synth/world.hpp"

namespace desplat::synth {

// Per view (index k of views.count): true when the view is a training view with distractors.
// m = round(ratio · #train) of the training views, spread evenly over them in view order:
// the j-th training view is cluttered when ⌊(j+1)·m/n⌋ > ⌊j·m/n⌋.
std::vector<bool> cluttered_views(int count, double clutter_ratio);

// The distractor objects of view `view`: spec.per_view of them, each centred on a random pixel
// of the central 70% of the image at a depth of spec.depth × the camera's distance to pose.target,
// with a diameter of spec.size × the image height. World frame; deterministic in (seed, view):
// two poses given the same `view` get the same objects at the same place in their frames.
std::vector<Primitive> make_distractors(const DistractorSpec& spec, const ViewPose& pose, const colmap::Camera& lens,
                                        uint64_t seed, int view);

}  // namespace desplat::synth
