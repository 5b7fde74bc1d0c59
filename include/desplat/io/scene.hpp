// A scene from a COLMAP capture: the registered photos as train/test views with undistorted
// pinhole cameras in the normalized world frame, the sparse points, and the normalization.
//
// Input layout (nerfstudio / 3DGS style):
//   <data_dir>/images/<name>       the photos, named as in the model (any format OpenImageIO reads)
//   <data_dir>/images_<N>/<name>   optional, the same photos downscaled N times
//   <data_dir>/sparse/0/           the COLMAP model, binary or text (colmap.hpp)
//   <data_dir>/distractor_masks/<name with its extension replaced by .png>
//                                  optional ground-truth distractor masks (masks.hpp); a view
//                                  without such a file (or a scene without the folder) has none
//   <data_dir>/masks/<name>.png or <name with its extension replaced by .png>
//                                  optional user masks of pixels to ignore (masks.hpp,
//                                  nerfstudio's convention: black = ignore); another folder
//                                  with SceneOptions::masks_dir
// The input is only read, never written (it may be on a read-only volume).
//
// Frames and units:
//   * World: the normalized frame of docs/METHOD.md §1, x_n = (x − center)·scale, with center =
//     mean of the camera centers of ALL registered images (before the split, as nerfstudio)
//     and scale = 1 / (largest |coordinate| of a centered camera center); scale = 1 when
//     there is one camera or all centers coincide. `normalization` maps back.
//   * Camera space is in normalized units too: p_cam = R·x_n + t' with R the image's
//     (orthonormal) COLMAP rotation and t' = (R·center + t)·scale, so depths are normalized.
//   * Intrinsics and sizes are those of the training resolution, pixel centers at +0.5.
//
// Resolution and undistortion, per view:
//   1. Training size: with downscale N, ⌊W/N⌋ × ⌊H/N⌋ of the model camera's W × H (nerfstudio's
//      floor rounding), unless images_N/ is used: it is when it holds every used view's file
//      with a size within one pixel of W/N × H/N (so ⌊·⌋ and round(·) folders both qualify), and
//      then its files' sizes are the training size. A mismatching or incomplete images_N/ is
//      ignored with a warning. N = 1 always reads images/.
//   2. The photo's lens at that size: rescale_camera (camera_models.hpp) of the model camera.
//   3. The training camera: undistort_camera (undistort.hpp, COLMAP's choice) of that lens;
//      SIMPLE_PINHOLE and PINHOLE lenses pass through unchanged.
//   Pixels: the source photo, resized with INTER_AREA when it is not already at the training
//   size, then undistorted with undistort_image. Photos that need either step are processed
//   once and cached as 8-bit PNG under cache_dir (never inside the input), keyed by the
//   source file's absolute path, byte size and modification time, the downscale and both
//   cameras, so a changed source or camera never reuses a stale file. Photos that need
//   neither step are read directly.
//
// Errors: every problem is a SceneError whose message names the offending file or folder and
// the problem (missing images/ or sparse/0/, a model problem reported by the COLMAP reader —
// duplicate names, NaN/Inf in poses or points, …, a registered image without a file, an
// unreadable image, an image whose size disagrees with its camera, a bad split).
// A model without 3D points loads, with a warning, and zero points.
//
// Ownership and threads: Scene is a plain value. load_view_image only reads the Scene and may
// be called concurrently; concurrent writers of the same cache file are safe (each writes a
// temporary file and renames it into place).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/world_frame.hpp"
#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/io/splits.hpp"
#include "desplat/io/undistort.hpp"

namespace desplat {

struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

using WarningSink = std::function<void(const std::string&)>;
// Passes `message` to `sink`, or prints "desplat: warning: <message>" on stderr when it is empty.
void report_warning(const WarningSink& sink, const std::string& message);

struct SceneOptions {
  int downscale = 1;                // 1, 2, 4, 8, … (any integer ≥ 1)
  std::filesystem::path cache_dir;  // empty: default_cache_dir()
  SplitOptions split;               // default: every 8th image (by name) is a test view
  UndistortOptions undistort;       // default: COLMAP image_undistorter's defaults
  WarningSink on_warning;           // empty: "desplat: warning: …" on stderr
  // The user's masks (masks.hpp). Empty: <data_dir>/masks when that folder exists, else none.
  // Given: the folder must exist (SceneError otherwise).
  std::filesystem::path masks_dir;
};

struct SceneView {
  std::string name;                  // as in the model, relative to images/
  std::filesystem::path image_path;  // the file the pixels come from (images/ or images_N/)
  Camera camera;                     // undistorted pinhole, normalized world, training size
  bool is_test = false;
  uint32_t colmap_image_id = 0;
  colmap::Camera distorted_camera;          // the photo's lens at the training size
  colmap::Camera undistorted_camera;        // PINHOLE, training size (camera's intrinsics in double)
  int source_width = 0, source_height = 0;  // size of the pixels in image_path
  int photo_width = 0, photo_height = 0;    // the COLMAP camera's size: the photo in images/
  std::filesystem::path mask_path;          // ground-truth distractor mask; empty when there is none
  std::filesystem::path user_mask_path;     // the user's mask of pixels to ignore; empty when none
};

struct Scene {
  std::filesystem::path data_dir;                  // absolute
  std::filesystem::path masks_dir;                 // absolute: the user's masks folder in use; empty when none
  std::vector<SceneView> views;                    // Train and Test views sorted by name; Unused ones left out
  std::vector<std::array<float, 3>> points_xyz;    // [P] normalized frame
  std::vector<std::array<uint8_t, 3>> points_rgb;  // [P] 0..255
  std::vector<uint64_t> point_ids;                 // [P] COLMAP point3D ids, ascending
  // [P] How many distinct images the point's track holds (used by the split or not), and
  // which of `views` observe it (indices, ascending, each once).
  std::vector<uint32_t> point_track_images;
  std::vector<std::vector<uint32_t>> point_views;
  WorldNormalization normalization;  // normalized = (original − center)·scale
  int downscale = 1;
  std::filesystem::path cache_dir;    // absolute
  std::vector<std::string> warnings;  // every warning issued while loading
  WarningSink on_warning;             // for warnings of load_view_image

  std::vector<size_t> train_views() const;  // indices into views
  std::vector<size_t> test_views() const;
};

// Loads the model, checks every used view's image file (existence and header: size and
// readability), and builds the views; pixels are read later by load_view_image.
Scene load_colmap_scene(const std::filesystem::path& data_dir, const SceneOptions& options = {});

// The undistorted photo of views[view] at the training size, float RGB in [0, 1].
// Throws SceneError naming the file when it is missing, unreadable or has changed size.
FloatImage load_view_image(const Scene& scene, size_t view);

// The cache file load_view_image uses for the view as the source file is now (empty when
// the view is read directly). Does not create anything.
std::filesystem::path view_cache_path(const Scene& scene, size_t view);

// $XDG_CACHE_HOME/desplat, else $HOME/.cache/desplat, else <temp dir>/desplat-cache.
std::filesystem::path default_cache_dir();

}  // namespace desplat
