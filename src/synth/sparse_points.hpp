// The sparse model SfM would produce for the synthetic views: surface points of the static
// scene, each observed in every view that sees it, with realistic noise.
#pragma once

#include <vector>

#include "desplat/io/colmap.hpp"
#include "synth/camera_path.hpp"
#include "synth/world.hpp"

namespace desplat::synth {

struct SparseInput {
  const Primitives* statics = nullptr;
  const std::vector<Primitives>* distractors = nullptr;  // [views], empty sets for clean views
  const std::vector<ViewPose>* poses = nullptr;          // [views]
  colmap::Camera lens;
  PointsSpec spec;
  uint64_t seed = 0;
};

// Fills model.points (ids 1…) and the points2d of model.images (image id = view index + 1,
// which must already exist). A point is kept when at least spec.min_track views see it:
// in front of the camera, projecting into the image, not hidden by static geometry or that
// view's distractors, not at a grazing angle. Its stored position is the surface point plus
// isotropic Gaussian noise that reprojects to ≈ position_noise_px; each observation is the
// exact projection of the surface point plus N(0, observation_noise_px²) per axis; its color
// is the clean, lit surface color; its error the mean reprojection error of the stored point.
// Tries up to 20 × spec.count random pixels of random views to find spec.count points.
void add_sparse_points(const SparseInput& input, colmap::Model& model);

}  // namespace desplat::synth
