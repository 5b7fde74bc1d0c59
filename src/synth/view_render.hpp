// Ray-traced images of one view: s × s jittered samples per pixel (a box filter), the clean
// image of the static scene, and, when the view has distractors, the image with them and the
// mask of pixels they cover.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "synth/camera_path.hpp"
#include "synth/world.hpp"

namespace desplat::synth {

// The camera-plane point (x/z, y/z) of every sample of every pixel: [H, W, s·s]. All views
// share one lens, so the (for distorted lenses iterative) unprojection runs once per scene.
struct SampleGrid {
  int width = 0, height = 0, samples = 0;  // samples per pixel = s·s
  std::vector<Eigen::Vector2d> uv;
};
// Sample (a, b) of pixel (i, j) sits at (i + (a + r)/s, j + (b + r')/s) with r, r' uniform in
// [0, 1) (stratified jitter); s = 1 samples pixel centres. The ray of a sample is the lens's
// camera_from_image (camera_models.hpp).
SampleGrid make_sample_grid(const colmap::Camera& lens, int s, uint64_t seed);

struct StaticScene {
  Primitives objects;
  WorldSpec world;
  SkySpec sky;
};

struct ViewRender {
  FloatImage clean;                     // RGB, static scene only
  std::optional<FloatImage> cluttered;  // RGB with distractors; only when the view has some
  FloatImage mask;                      // 1 channel, 1 where > half the samples hit a distractor
  uint64_t distractor_ray_tests = 0, sky_evaluations = 0;
};

// `distractors` empty: no distractor work at all (cluttered stays empty, mask all 0).
// Parallel over rows (OpenMP); the result does not depend on the thread count.
ViewRender render_view(const StaticScene& scene, const Primitives& distractors, const ViewPose& pose,
                       const SampleGrid& grid);

}  // namespace desplat::synth
