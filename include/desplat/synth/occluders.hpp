// desplat_occlude's job: making a scene with known distractors by pasting occluders (opaque
// shapes and patches of other photos) into some training views of a real capture, with
// ground-truth distractor masks in the layout of masks.hpp (distractor_mask_path).
//
// Frames and units: boxes are [x0, y0, x1, y1] in pixels of the image's grid, x1 and y1
// exclusive (pixel (i, j) has its center at (i + 0.5, j + 0.5)).
//
// Ownership and threads: plain values, no shared state. occlude_scene writes only inside its
// output folder.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "desplat/io/splits.hpp"

namespace desplat {

struct OccludeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct OccludeOptions {
  std::filesystem::path data_dir;  // images/ + sparse/0/ (read only)
  std::filesystem::path out_dir;   // must not be data_dir or inside it
  double fraction = 0.5;           // share of the training views that get occluders, [0, 1]
  uint64_t seed = 1;
  double coverage_min = 0.05;  // covered share of an occluded view's pixels: 0 < min ≤ max ≤ 0.6
  double coverage_max = 0.25;
  int track_length = 1;    // consecutive training views that share one set of occluders, ≥ 1
  SplitOptions split;      // which views are training views (default: every 8th is a test view)
  bool overwrite = false;  // replace images/, sparse/, distractor_masks/, occluders.json in out_dir
};

// One pasted occluder. Kinds: "ellipse", "rectangle", "polygon" (opaque, one random colour),
// "patch_rectangle", "patch_ellipse" (pixels cut from another photo of the capture at
// source_box and pasted at a box that does not overlap it).
struct Occluder {
  std::string kind;
  std::array<int, 4> box{};         // bounding box of the pasted pixels, [x0, y0, x1, y1)
  std::array<uint8_t, 3> color{};   // opaque shapes only
  std::string source_image;         // patches only: the photo the pixels come from
  std::array<int, 4> source_box{};  // patches only: where, in source_image (box moved by an offset)
};

struct OccludedView {
  std::string name;
  ViewRole role = ViewRole::Train;
  bool occluded = false;
  double covered_fraction = 0;  // pasted pixels / all pixels
  std::vector<Occluder> occluders;
};

struct OccludeReport {
  std::vector<OccludedView> views;  // every registered image, sorted by name
};

// Writes out_dir/ as a scene: sparse/0/ (the input's files, byte copies), images/ (every
// registered image; test, unused and untouched training views are byte copies, occluded
// views are re-encoded in their own format — JPEG at quality 95, 4:4:4 — under the same name),
// distractor_masks/ for every training view (8-bit grey, 255 where an occluder was pasted,
// all 0 for untouched views; none for test views) and occluders.json (the report).
// round(fraction · #train) training views, chosen from the seed, get 1–3 occluders whose union
// covers [coverage_min, coverage_max] of the image. With track_length L > 1 the training views
// (sorted by name) are cut into runs of L consecutive views, round(fraction · #train / L) runs
// are chosen, and every view of a run gets the same occluders at the same pixels (photos of the
// same size; a run's photos of another size draw their own): something
// that stays in the frame while the camera moves (a thumb on the lens, a person walking along),
// which no single 3D position explains. Same inputs and seed give identical files.
// images_N/ folders of the input are not copied (they would show the unoccluded photos).
// Throws OccludeError naming the file or option on bad input (missing/unreadable files, a bad
// model or split, out_dir inside data_dir, out_dir already holding a scene without overwrite,
// options out of range).
OccludeReport occlude_scene(const OccludeOptions& options);

}  // namespace desplat
