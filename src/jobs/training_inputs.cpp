// desplat_train's inputs: SfM on a folder of photos, the scene, the resumed model's record and
// the training data, all checked before the output folder is written.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "desplat/io/image_io.hpp"
#include "desplat/io/masks.hpp"
#include "desplat/jobs/sfm_run.hpp"
#include "jobs/training_steps.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// What SfM made of the user's photos, including every file and photo it left out.

}  // namespace

bool load_view_photo(const Scene& scene, size_t i, ByteImage& photo, std::vector<uint8_t>& keep) {
  // Held in 8 bits (a quarter of float's memory): exact for 8-bit photos and the loader's
  // 8-bit cache; deeper files are rounded, and the return value says so (docs/METHOD.md §6).
  const FloatImage full = load_view_image(scene, i);
  photo = to_bytes(full);
  bool rounded = false;
  for (size_t k = 0; k < full.pixels.size() && !rounded; ++k)
    rounded = byte_to_float(photo.pixels[k]) != full.pixels[k];
  keep.clear();
  if (!scene.views[i].user_mask_path.empty()) {
    const std::vector<float> mask = load_view_keep_mask(scene, i);  // exactly 0 or 1
    keep.assign(mask.begin(), mask.end());
    // What the mask hides is never read: zero it, so no rule can use it by accident.
    for (size_t p = 0; p < keep.size(); ++p)
      if (keep[p] == 0) photo.pixels[3 * p] = photo.pixels[3 * p + 1] = photo.pixels[3 * p + 2] = 0;
  }
  return rounded;
}

TrainingData load_training_data(const Scene& scene, int rank, int ranks) {
  TrainingData data;
  data.points = scene.points_xyz;
  data.colors = scene.points_rgb;
  data.normalization = scene.normalization;
  std::vector<TrainView> views(scene.views.size());
  std::vector<uint8_t> rounded(scene.views.size(), 0);  // the photo had values 8 bits do not hold
  // Each view's index among the training or the test views decides its rank (rank_of_view).
  std::vector<uint8_t> held(scene.views.size(), 1);
  for (size_t i = 0, train = 0, test = 0; i < scene.views.size(); ++i)
    held[i] = rank_of_view(scene.views[i].is_test ? test++ : train++, ranks) == rank;
  std::string error;
#pragma omp parallel for schedule(dynamic)
  for (size_t i = 0; i < scene.views.size(); ++i) {
    views[i] = {scene.views[i].name, scene.views[i].camera, {}, {}};
    if (!held[i]) continue;  // another rank's
    try {
      rounded[i] = load_view_photo(scene, i, views[i].image, views[i].keep);
    } catch (const std::exception& e) {
#pragma omp critical
      error = e.what();
    }
  }
  if (!error.empty()) throw SceneError(error);
  if (const auto n = std::count(rounded.begin(), rounded.end(), 1); n > 0) {
    const std::string first = scene.views[size_t(std::find(rounded.begin(), rounded.end(), 1) - rounded.begin())].name;
    const std::string message = std::to_string(n) + " of " + std::to_string(rounded.size()) +
                                " photos (first: " + first +
                                ") hold more than 8 bits per channel or values outside [0, 1]; training rounds them "
                                "to 8 bits, clamped to [0, 1]";
    report_warning(scene.on_warning, message);
  }
  std::vector<int32_t> train_index(views.size(), -1);  // scene view → index into data.train
  for (size_t i = 0; i < views.size(); ++i) {
    if (!scene.views[i].is_test) train_index[i] = int32_t(data.train.size());
    (scene.views[i].is_test ? data.test : data.train).push_back(std::move(views[i]));
  }
  // The tracks, for transient_points (train/transient_points.hpp).
  if (scene.point_views.size() == scene.points_xyz.size() &&
      scene.point_track_images.size() == scene.points_xyz.size()) {
    data.point_track_images = scene.point_track_images;
    data.point_train_views.resize(scene.point_views.size());
    for (size_t p = 0; p < scene.point_views.size(); ++p)
      for (const uint32_t v : scene.point_views[p])
        if (v < train_index.size() && train_index[v] >= 0) data.point_train_views[p].push_back(train_index[v]);
  }
  return data;
}

RunInputs load_run_inputs(const TrainingRunOptions& opt, int rank, int ranks) {
  RunInputs in;
  const ModelFolder model(opt.out_dir);
  if (opt.resume) {
    if (!model.has_checkpoint())
      throw std::invalid_argument("--resume: no checkpoint at " + model.checkpoint_path().string() +
                                  ": train the model first, or drop --resume to start a new run");
    in.resumed = model.read_config();
  }
  in.data_dir = opt.data_dir;
  if (!opt.images_dir.empty()) {
    SfmForTraining sfm = run_sfm_for_training(opt.images_dir, opt.out_dir / "sfm");
    in.sfm_summary = std::move(sfm.metrics);
    in.data_dir = sfm.data_dir;
  }
  SceneOptions scene_options;
  // A resumed model is continued at the size it was trained at unless --downscale says otherwise
  // (and then the scene check below refuses a different size).
  scene_options.downscale = opt.downscale.value_or(in.resumed ? in.resumed->scene.downscale : 1);
  scene_options.split = opt.split;
  scene_options.masks_dir = opt.masks_dir;
  in.scene = load_colmap_scene(in.data_dir, scene_options);
  in.recipe = SceneRecipe::of(in.scene, in.data_dir, scene_options);
  if (in.resumed) {
    // Continuing on other views or at another size would silently train another model.
    const std::string changed = in.resumed->scene.difference(in.recipe);
    if (!changed.empty())
      throw std::invalid_argument("--resume: the scene is not the one " + opt.out_dir.string() +
                                  " was trained on: " + changed);
  }
  in.data = load_training_data(in.scene, rank, ranks);
  return in;
}

}  // namespace desplat
