// Re-rendering a saved model: the scene (cameras only) is loaded again from the data
// folder recorded in the model's config.json; the Gaussians come from its checkpoint.
#include "desplat/jobs/render_run.hpp"
#include "desplat/io/output_folder.hpp"

#include "desplat/jobs/model_folder.hpp"

#include <algorithm>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "desplat/io/checkpoint.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/raster/composite.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/trainer.hpp"
#include "desplat/train/training_checkpoint.hpp"

namespace desplat {
namespace fs = std::filesystem;
namespace {

// Straight (unpremultiplied) RGBA: what image viewers and compositors expect in a PNG.
FloatImage with_alpha(const FloatImage& rgb_over_black, const FloatImage& alpha) {
  FloatImage out{rgb_over_black.width, rgb_over_black.height, 4, {}};
  out.pixels.resize(alpha.pixels.size() * 4);
  for (size_t p = 0; p < alpha.pixels.size(); ++p) {
    const float a = alpha.pixels[p];
    for (int c = 0; c < 3; ++c) out.pixels[4 * p + c] = a > 0 ? rgb_over_black.pixels[3 * p + c] / a : 0.0f;
    out.pixels[4 * p + 3] = a;
  }
  return out;
}

std::vector<size_t> listed_views(const Scene& scene, const std::string& views, const std::string& data_dir) {
  std::vector<size_t> chosen;
  if (views == "test") return scene.test_views();
  if (views == "train") return scene.train_views();
  if (views == "all") {
    for (size_t i = 0; i < scene.views.size(); ++i) chosen.push_back(i);
    return chosen;
  }
  std::stringstream names(views);
  std::string name;
  while (std::getline(names, name, ',')) {
    size_t i = 0;
    while (i < scene.views.size() && scene.views[i].name != name) ++i;
    if (i == scene.views.size()) throw std::invalid_argument("no view named '" + name + "' in " + data_dir);
    chosen.push_back(i);
  }
  return chosen;
}

// The views --views names; refused when that is none (an empty list, or a split without them).
std::vector<size_t> choose_views(const Scene& scene, const std::string& views, const std::string& data_dir) {
  std::vector<size_t> chosen = listed_views(scene, views, data_dir);
  if (chosen.empty())
    throw std::invalid_argument("--views '" + views + "' selects no view of the model's scene " + data_dir + " (" +
                                std::to_string(scene.train_views().size()) + " training and " +
                                std::to_string(scene.test_views().size()) +
                                " test views): give test, train, all or image names separated by commas");
  return chosen;
}

}  // namespace

int run_render(const RenderRunOptions& o) {
  if (o.layer != "static" && o.layer != "distractor" && o.layer != "composite")
    throw std::invalid_argument("unknown layer '" + o.layer + "' (static, distractor or composite)");
  const ModelFolder model(o.model_dir);
  const ModelFolder::Config config = model.read_config();
  const TrainConfig& train = config.train;
  const std::string data_dir = config.scene.data_dir.string();
  check_output_folder("--out", o.out_dir, {{"--model", o.model_dir, true}, {"the model's data folder", data_dir}});
  const Scene scene = load_colmap_scene(data_dir, config.scene.reopen_options());
  const Checkpoint ckpt = model.read_checkpoint();
  const GaussianSet statics = gaussians_from_checkpoint(ckpt);
  std::map<std::string, size_t> buffer_of;  // training view name → distractor buffer
  const std::vector<std::string> buffer_views = distractor_views_in_checkpoint(ckpt);
  for (size_t b = 0; b < buffer_views.size(); ++b) buffer_of[buffer_views[b]] = b;

  // --appearance: the chosen training photo's embeddings recolour the static layer (appearance
  // model) and give the background behind it (background model).
  AppearanceModel look;
  BackgroundModel sky;
  std::vector<float> embedding, sky_embedding;
  if (!o.appearance.empty()) {
    const std::vector<std::string> look_views = appearance_views_in_checkpoint(ckpt);
    const std::vector<std::string> sky_views = background_views_in_checkpoint(ckpt);
    if (look_views.empty() && sky_views.empty())
      throw std::invalid_argument("--appearance: " + o.model_dir.string() +
                                  " was trained without an appearance or background model (train with --effects "
                                  "…,appearance or …,background)");
    const std::vector<std::string>& names = look_views.empty() ? sky_views : look_views;
    const auto at = std::find(names.begin(), names.end(), o.appearance);
    if (at == names.end())
      throw std::invalid_argument("--appearance: '" + o.appearance + "' is not a training view of " +
                                  o.model_dir.string() + " (only training photos have an appearance)");
    const size_t index = size_t(at - names.begin());
    if (!look_views.empty()) {
      look = appearance_from_checkpoint(ckpt);
      const std::span<const float> e = look.embedding(index);
      embedding.assign(e.begin(), e.end());
    }
    if (!sky_views.empty()) {
      sky = background_from_checkpoint(ckpt);
      const std::span<const float> e = sky.embedding(index);
      sky_embedding.assign(e.begin(), e.end());
      if (sky.settings.share_appearance_embedding) {  // the authors' form
        if (embedding.empty())
          throw CheckpointError(o.model_dir.string() +
                                ": its background model reads the appearance embeddings, but the model has none");
        sky_embedding = embedding;
      }
    }
  }
  AppearancePass look_pass;
  std::function<void(RasterOutput&)> recolor;
  if (!embedding.empty())
    recolor = [&](RasterOutput& fw) { look_pass.forward(look, embedding, statics, fw, o.threads); };

  const std::vector<size_t> chosen = choose_views(scene, o.views, data_dir);
  const bool wants_distractors = o.layer != "static" || o.mask || o.figure;
  for (size_t i : chosen) {
    if (!wants_distractors || buffer_of.count(scene.views[i].name)) continue;
    const std::string what = o.layer != "static" ? "layer '" + o.layer + "'" : o.mask ? "--mask" : "--figure";
    if (buffer_views.empty())
      throw std::invalid_argument(what + " needs a DeSplat model; " + o.model_dir.string() +
                                  " was trained --static-only (use --layer static)");
    throw std::invalid_argument(what + ": view '" + scene.views[i].name +
                                "' is not a training view, so it has no distractors (only --layer static exists there; "
                                "use --views train)");
  }

  RasterSettings rs;
  rs.num_threads = o.threads;
  // The degree training ended at (a run stopped early has not trained the higher bands).
  rs.active_sh_degree = std::min(statics.sh_degree, train.sh_degree_at(ckpt.metadata.value("step", int64_t(0))));
  int written = 0;
  for (size_t i : chosen) {
    const SceneView& view = scene.views[i];
    const auto buffer = buffer_of.find(view.name);
    GaussianSet distractors;
    if (buffer != buffer_of.end()) distractors = distractors_from_checkpoint(ckpt, buffer->second);
    const GaussianSet* d = buffer != buffer_of.end() ? &distractors : nullptr;
    // With --alpha the layer over black is its premultiplied color; otherwise it is shown over
    // the chosen photo's learned background (--appearance of a model with one) or the
    // evaluation background. The mask does not depend on the background.
    BackgroundPass sky_pass;
    const bool learned_bg = !sky_embedding.empty() && !o.alpha;
    if (learned_bg)
      sky_pass.forward(sky, sky_embedding, view.camera,
                       train.background.sh_degree_at(ckpt.metadata.value("step", int64_t(0))), o.threads);
    const Background bg = o.alpha      ? Background(std::array<float, 3>{0, 0, 0})
                          : learned_bg ? sky_pass.background()
                                       : Background(train.eval_background);
    const ViewLayers layers = render_view_layers(statics, d, view.camera, rs, bg, recolor);
    const fs::path stem = o.out_dir / fs::path(view.name).replace_extension();
    const FloatImage& image = o.layer == "static"       ? layers.statics
                              : o.layer == "distractor" ? layers.distractor
                                                        : layers.composite;
    if (o.alpha) {
      FloatImage alpha = o.layer == "static" ? layers.static_alpha : layers.distractor_alpha;
      if (o.layer == "composite")
        for (size_t p = 0; p < alpha.pixels.size(); ++p)
          alpha.pixels[p] = 1 - (1 - layers.static_alpha.pixels[p]) * (1 - layers.distractor_alpha.pixels[p]);
      write_image(stem.string() + ".png", with_alpha(image, alpha));
    } else {
      write_image(stem.string() + ".png", image);
    }
    ++written;
    if (o.mask) write_image(stem.string() + "_mask.png", distractor_mask(layers)), ++written;
    if (o.figure) {
      const FloatImage truth = load_view_image(scene, i);
      const FloatImage row = layers_figure_row(
          truth, o.alpha ? render_view_layers(statics, d, view.camera, rs, train.eval_background, recolor) : layers);
      write_image(stem.string() + "_row.png", row), ++written;
    }
  }
  return written;
}

}  // namespace desplat
