// Ground-truth distractor masks: reading them for a scene's views and scoring predicted masks
// against them. Making a scene with known distractors by pasting occluders into a real capture
// (desplat_occlude) is occluders.hpp.
//
// Mask files (the layout desplat_occlude and the synthetic generator write):
//   <data_dir>/distractor_masks/<image name with its extension replaced by .png>
//   e.g. images/0002.jpg -> distractor_masks/0002.png, images/cam0/a.JPG -> distractor_masks/cam0/a.png.
//   Any bit depth and channel count; only the first channel is used, scaled to [0, 1] by the
//   format's full range; a value > 0.5 marks a distractor pixel. A mask has the size of the
//   photo in images/ (its COLMAP camera's size), also when training reads images_N/.
//   load_colmap_scene fills SceneView::mask_path for the views that have such a file.
//
// User masks (nerfstudio's convention, also COLMAP's file naming): pixels to leave out of
// training and evaluation, e.g. the photographer's shadow or a car the user already knows is
// there. One PNG per photo, in <data_dir>/masks/ (or SceneOptions::masks_dir), named
// <image name>.png (COLMAP: 0002.jpg.png) or <image name with its extension replaced by .png>
// (nerfstudio: 0002.png), the first tried first. The photo's size; the first channel is used;
// black (≤ 0.5) = ignore, white = use. A view without a file uses every pixel.
//
// Frames and units: masks are row-major [H, W] in the image's pixel grid (pixel (i, j) has its
// center at (i + 0.5, j + 0.5)).
//
// Ownership and threads: plain values, no shared state. load_view_mask may run concurrently.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "desplat/io/image_io.hpp"
#include "desplat/io/scene.hpp"

namespace desplat {

// <data_dir>/distractor_masks/<image_name with its extension replaced by .png>.
std::filesystem::path distractor_mask_path(const std::filesystem::path& data_dir, const std::string& image_name);

// The mask of views[view] as a 1-channel float image in [0, 1] at the view's training size,
// through the same geometry as load_view_image: resized with INTER_AREA to the training size
// when needed, then undistorted with undistort_image (bilinear, so edge pixels get fractional
// values; threshold at 0.5). A mask pixel therefore lines up with the image pixel.
// Not cached: masks are read once per view. Throws SceneError naming the file when the view
// has no mask (mask_path empty), the file is unreadable, or its size is not the photo's.
FloatImage load_view_mask(const Scene& scene, size_t view);

// The user's mask of views[view] as [H·W] at the training size, 1 = use, 0 = ignore, through
// the geometry of load_view_image. A training pixel is used only when every photo pixel that
// contributes to it (resizing, bilinear undistortion) is: a pixel that mixes in an ignored one
// is ignored too. Throws SceneError naming the file when the view has no user mask
// (user_mask_path empty), the file is unreadable, or its size is not the photo's.
std::vector<float> load_view_keep_mask(const Scene& scene, size_t view);

struct MaskScore {
  double iou = 1;                 // |P ∩ T| / |P ∪ T|; 1 when both are empty
  double predicted_fraction = 0;  // |P| / pixels
  double truth_fraction = 0;      // |T| / pixels
};

// P = predicted > threshold, T = truth > 0.5, both [H·W]. Throws std::invalid_argument when
// the sizes differ. Take a mean IoU only over views whose truth is non-empty: on a clean view
// the IoU is 0 or 1 and says nothing about quality; report predicted_fraction there instead
// (it is the false-positive area).
MaskScore score_mask(std::span<const float> predicted, std::span<const float> truth, float threshold = 0.5f);

}  // namespace desplat
