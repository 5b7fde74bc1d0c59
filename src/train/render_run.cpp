// Re-rendering a saved model: the scene (cameras only) is loaded again from the data
// folder recorded in the model's config.json; the Gaussians come from its checkpoint.
#include "desplat/render_run.hpp"

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "desplat/checkpoint.hpp"
#include "desplat/image_io.hpp"
#include "desplat/raster.hpp"
#include "desplat/scene.hpp"
#include "desplat/train_config_json.hpp"
#include "desplat/trainer.hpp"
#include "desplat/training_checkpoint.hpp"

namespace desplat {
namespace fs = std::filesystem;

int run_render(const RenderRunOptions& o) {
  const fs::path config_path = o.model_dir / "config.json", ckpt_path = o.model_dir / "checkpoint.ckpt";
  std::ifstream f(config_path);
  if (!f) throw std::invalid_argument("not a desplat model folder: cannot read " + config_path.string());
  nlohmann::json cfg;
  try {
    f >> cfg;
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(config_path.string() + " is not valid JSON: " + e.what());
  }
  if (o.layer != "static") {
    if (o.layer == "distractor" || o.layer == "composite")
      throw std::invalid_argument("layer '" + o.layer + "' needs a DeSplat model with distractors; " +
                                  o.model_dir.string() + " holds static Gaussians only (use --layer static)");
    throw std::invalid_argument("unknown layer '" + o.layer + "' (static, distractor or composite)");
  }
  const TrainConfig train = config_from_json(cfg.at("train"));
  const nlohmann::json& run = cfg.at("run");
  SceneOptions scene_options;
  scene_options.downscale = run.at("downscale").get<int>();
  scene_options.split.rule = SplitRule(run.at("split_rule").get<int>());
  scene_options.split.every_nth = run.at("split_every_nth").get<int>();
  const Scene scene = load_colmap_scene(run.at("data_dir").get<std::string>(), scene_options);
  const Checkpoint ckpt = read_checkpoint(ckpt_path);
  const GaussianSet gaussians = gaussians_from_checkpoint(ckpt);

  std::vector<size_t> chosen;
  if (o.views == "test") chosen = scene.test_views();
  else if (o.views == "train") chosen = scene.train_views();
  else if (o.views == "all") for (size_t i = 0; i < scene.views.size(); ++i) chosen.push_back(i);
  else {
    std::stringstream names(o.views);
    std::string name;
    while (std::getline(names, name, ',')) {
      size_t i = 0;
      while (i < scene.views.size() && scene.views[i].name != name) ++i;
      if (i == scene.views.size()) throw std::invalid_argument("no view named '" + name + "' in " + run.at("data_dir").get<std::string>());
      chosen.push_back(i);
    }
  }
  RasterSettings rs;
  rs.num_threads = o.threads;
  rs.active_sh_degree = gaussians.sh_degree;
  RasterOutput out;
  for (size_t i : chosen) {
    const Camera& cam = scene.views[i].camera;
    rasterize_forward(gaussians.view(), cam, rs, out);
    const FloatImage img = composite_over_background(out, train.eval_background);
    write_image(o.out_dir / fs::path(scene.views[i].name).replace_extension(".png"), img);
  }
  return static_cast<int>(chosen.size());
}

}  // namespace desplat
