// desplat_render's job: re-render views of a trained model (desplat_train's --out).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace desplat {

struct RenderRunOptions {
  std::filesystem::path model_dir;  // desplat_train's --out (config.json + checkpoint.ckpt)
  std::filesystem::path out_dir;    // one PNG per view
  std::string layer = "static";     // static | distractor | composite (the latter need DeSplat models)
  std::string views = "test";       // test | train | all | comma-separated image names
  int threads = 0;
};

// Returns the number of images written. Throws with a clear message for bad input
// (missing model files, unknown view names, a layer the model does not have).
int run_render(const RenderRunOptions& options);

}  // namespace desplat
