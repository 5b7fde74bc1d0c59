// desplat_render's job: re-render views of a trained model (desplat_train's --out).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace desplat {

struct RenderRunOptions {
  std::filesystem::path model_dir;  // desplat_train's --out (config.json + checkpoint.ckpt)
  std::filesystem::path out_dir;    // one PNG per view
  // static | distractor | composite. The last two exist only for training views of a
  // DeSplat model (each training view has its own distractors); test and novel views
  // have the static layer only. Layers are shown over the evaluation background.
  std::string layer = "static";
  std::string views = "test";  // test | train | all | comma-separated image names
  bool mask = false;           // also <name>_mask.png: the distractor mask A_d > 0.5 (training views)
  bool alpha = false;          // write the layer as straight RGBA (alpha = the layer's coverage)
  bool figure = false;         // also <name>_row.png: truth | static | distractor | composite | mask
  // A training view's name: the static layer in that photo's appearance (models trained with
  // --effects …,appearance) over that photo's learned background (…,background). Empty: the
  // plain colours (what point_cloud.ply holds) over the evaluation background.
  std::string appearance;
  int threads = 0;
};

// Writes <out_dir>/<image name>.png per view (plus the extras asked for) and returns the
// number of files written. Throws with a clear message for bad input (missing model
// files, unknown view names, a layer, mask or figure asked of a view that has no
// distractors or of a static-only model, --appearance of a model without either per-image
// model or naming a
// view that is not a training view).
int run_render(const RenderRunOptions& options);

}  // namespace desplat
