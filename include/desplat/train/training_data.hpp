// What a Trainer trains on: the training and test views (undistorted pinhole cameras and
// 8-bit photos, normalized world frame, docs/METHOD.md §1) and the sparse points.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/image.hpp"
#include "desplat/core/world_frame.hpp"

namespace desplat {

struct TrainView {
  std::string name;
  Camera camera;    // undistorted pinhole, normalized frame, full training resolution
  ByteImage image;  // [H, W, 3] matching the camera, 8 bits per channel (core/image.hpp)
  // Optional [H·W], the user's mask (docs/METHOD.md §4, masks): 1 = use the pixel, 0 = ignore
  // it; empty = use every pixel. One byte per pixel, like the photo's channels: a float mask
  // would take more memory than the photo. An ignored pixel leaves the loss, SSIM, the
  // regularizers, the residual statistics, the densification statistics and the metrics; its
  // image value is never read for training (the loader sets it to 0).
  std::vector<uint8_t> keep;
};

// In a job of several ranks (docs/METHOD.md §6, ranks) each rank's TrainingData holds the
// photos and masks of its own views only: view i of `train`, and view i of `test`, belongs to
// rank rank_of_view(i, ranks); the other views keep their name and camera, with an empty image.
inline int rank_of_view(size_t index, int ranks) { return int(index % size_t(ranks)); }

struct TrainingData {
  std::vector<TrainView> train, test;
  std::vector<std::array<float, 3>> points;  // normalized frame
  std::vector<std::array<uint8_t, 3>> colors;
  // Optional, [points] or both empty: how many images each point's track holds, and which
  // training views (indices into `train`) observe it (transient_points.hpp).
  std::vector<uint32_t> point_track_images;
  std::vector<std::vector<int32_t>> point_train_views;
  WorldNormalization normalization;
};

}  // namespace desplat
