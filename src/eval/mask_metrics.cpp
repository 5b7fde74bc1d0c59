#include "desplat/eval/mask_metrics.hpp"

#include <map>
#include <stdexcept>

#include "desplat/raster/composite.hpp"
#include "desplat/raster/raster.hpp"

namespace desplat {

MaskMetrics evaluate_distractor_masks(const Trainer& trainer, const Scene& scene) {
  std::map<std::string, size_t> scene_view;
  for (size_t i = 0; i < scene.views.size(); ++i)
    if (!scene.views[i].mask_path.empty()) scene_view[scene.views[i].name] = i;
  MaskMetrics out;
  if (scene_view.empty()) return out;
  double iou_sum = 0, false_positive_sum = 0;
  const std::vector<TrainView>& train = trainer.data().train;
  for (size_t v = 0; v < train.size(); ++v) {
    const auto found = scene_view.find(train[v].name);
    if (found == scene_view.end()) continue;
    const FloatImage truth = load_view_mask(scene, found->second);
    // The mask is A_d > 0.5: only the view's distractors need rasterizing.
    const Camera& cam = train[v].camera;
    FloatImage predicted{cam.width, cam.height, 1, std::vector<float>(size_t(cam.width) * cam.height, 0.0f)};
    if (!trainer.distractors().empty() && trainer.distractors()[v].size() > 0) {
      RasterOutput d;
      rasterize_forward(trainer.distractors()[v].params.view(), cam, trainer.raster_settings(), d);
      for (size_t p = 0; p < d.alpha.size(); ++p)
        predicted.pixels[p] = d.alpha[p] > kDistractorMaskThreshold ? 1.0f : 0.0f;
    }
    if (truth.width != predicted.width || truth.height != predicted.height)
      throw std::invalid_argument("distractor mask of view '" + train[v].name + "' is " + std::to_string(truth.width) +
                                  "x" + std::to_string(truth.height) + " but the training view is " +
                                  std::to_string(predicted.width) + "x" + std::to_string(predicted.height));
    const MaskScore s = score_mask(predicted.pixels, truth.pixels);
    out.views.push_back({train[v].name, s});
    if (s.truth_fraction > 0) {
      iou_sum += s.iou, ++out.occluded_views;
    } else {
      false_positive_sum += s.predicted_fraction, ++out.clean_views;
    }
  }
  if (out.occluded_views) out.mean_iou = iou_sum / out.occluded_views;
  if (out.clean_views) out.mean_clean_view_false_positive = false_positive_sum / out.clean_views;
  return out;
}

}  // namespace desplat
