// Ground-truth distractor masks: reading them for a scene's views and scoring predicted masks.
// See include/desplat/io/masks.hpp for the conventions implemented here. desplat_occlude's
// occluder pasting lives in occluders.cpp.
#include "desplat/io/masks.hpp"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "desplat/io/undistort.hpp"
#include "image_read_helpers.hpp"

namespace desplat {

namespace fs = std::filesystem;

namespace {

// The first channel of any image file, scaled to [0, 1] by its format's full range.
// Values as stored (unassociated_alpha).
FloatImage read_first_channel(const fs::path& path, const std::string& kind) {
  const OIIO::ImageSpec config = unassociated_alpha();
  auto in = OIIO::ImageInput::open(path.string(), &config);
  if (!in) throw SceneError(path.string() + ": cannot read the " + kind + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw SceneError(path.string() + ": the " + kind + " has no pixels");
  FloatImage mask{spec.width, spec.height, 1, std::vector<float>(size_t(spec.width) * spec.height)};
  if (!in->read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, mask.pixels.data()))
    throw SceneError(path.string() + ": cannot decode the " + kind + ": " + in->geterror());
  for (float& v : mask.pixels) {
    if (!std::isfinite(v)) throw SceneError(path.string() + ": the " + kind + " contains NaN or Inf");
    v = std::clamp(v, 0.0f, 1.0f);  // float files may hold anything; the convention is [0, 1]
  }
  return mask;
}

}  // namespace

fs::path distractor_mask_path(const fs::path& data_dir, const std::string& image_name) {
  return data_dir / "distractor_masks" / fs::path(image_name).replace_extension(".png");
}

namespace {

const SceneView& view_at(const Scene& scene, size_t view) {
  if (view >= scene.views.size())
    throw SceneError("view " + std::to_string(view) + " does not exist (the scene has " +
                     std::to_string(scene.views.size()) + ")");
  return scene.views[view];
}

// A photo-sized mask read from `path` through the geometry of load_view_image (scene.hpp:
// resize, then undistort), as [0, 1] values at the training size.
FloatImage to_training_geometry(const SceneView& v, FloatImage mask, const fs::path& path, const std::string& kind) {
  if (mask.width != v.photo_width || mask.height != v.photo_height)
    throw SceneError(path.string() + ": " + kind + " is " + size_text(mask.width, mask.height) + " px but the photo '" +
                     v.name + "' is " + size_text(v.photo_width, v.photo_height) + " px");
  try {
    mask = resize_area(mask, int(v.distorted_camera.width), int(v.distorted_camera.height));
    return undistort_image(mask, v.distorted_camera, v.undistorted_camera);
  } catch (const std::invalid_argument& e) {
    throw SceneError(path.string() + ": " + e.what());
  }
}

}  // namespace

FloatImage load_view_mask(const Scene& scene, size_t view) {
  const SceneView& v = view_at(scene, view);
  if (v.mask_path.empty())
    throw SceneError(distractor_mask_path(scene.data_dir, v.name).string() + ": view '" + v.name +
                     "' has no distractor mask");
  return to_training_geometry(v, read_first_channel(v.mask_path, "distractor mask"), v.mask_path, "distractor mask");
}

std::vector<float> load_view_keep_mask(const Scene& scene, size_t view) {
  const SceneView& v = view_at(scene, view);
  if (v.user_mask_path.empty()) throw SceneError("view '" + v.name + "' has no mask of pixels to ignore");
  // Binarize at the photo's resolution first, so "black = ignore" means the same whatever
  // grey levels an editor left on the edges.
  FloatImage photo_mask = read_first_channel(v.user_mask_path, "mask");
  for (float& m : photo_mask.pixels) m = m > 0.5f ? 1.0f : 0.0f;
  const FloatImage mask = to_training_geometry(v, std::move(photo_mask), v.user_mask_path, "mask");
  // Kept only when all that contributes is kept (a mean of ones is 1 up to float rounding).
  std::vector<float> keep(mask.pixels.size());
  for (size_t i = 0; i < keep.size(); ++i) keep[i] = mask.pixels[i] >= 1.0f - 1e-5f ? 1.0f : 0.0f;
  return keep;
}

MaskScore score_mask(std::span<const float> predicted, std::span<const float> truth, float threshold) {
  if (predicted.size() != truth.size())
    throw std::invalid_argument("score_mask: predicted mask has " + std::to_string(predicted.size()) +
                                " pixels but the truth has " + std::to_string(truth.size()));
  size_t both = 0, either = 0, p_count = 0, t_count = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    const bool p = predicted[i] > threshold, t = truth[i] > 0.5f;
    both += p && t;
    either += p || t;
    p_count += p;
    t_count += t;
  }
  MaskScore s;
  const double n = truth.empty() ? 1.0 : double(truth.size());
  s.iou = either == 0 ? 1.0 : double(both) / double(either);
  s.predicted_fraction = double(p_count) / n;
  s.truth_fraction = double(t_count) / n;
  return s;
}

}  // namespace desplat
