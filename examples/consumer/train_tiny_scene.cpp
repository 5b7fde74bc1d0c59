// Generates a tiny synthetic scene and trains on it for a few steps through desplat's public
// API, as desplat_train does, then checks that the run wrote a sane model.
//   train_tiny_scene OUT_DIR      (OUT_DIR/scene: the scene, OUT_DIR/model: the trained model)
// Exit code 0 when every check passes; otherwise one line naming the failed check.
#include <atomic>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "desplat/io/ply.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/synth/synth.hpp"

namespace fs = std::filesystem;
namespace synth = desplat::synth;

namespace {

constexpr int kSteps = 60;

int fail(const std::string& what) {
  std::fprintf(stderr, "train_tiny_scene: %s\n", what.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) return fail("usage: train_tiny_scene OUT_DIR");
  const fs::path out = argv[1];
  try {
    // The default description: 8 views of 64×48 px around a small textured world (synth.hpp).
    synth::GenerateOptions generate;
    generate.out = out / "scene";
    generate.overwrite = true;
    const synth::GenerationReport scene = synth::generate_scene(synth::Description{}, generate);
    std::printf("scene: %d training and %d test views, %zu sparse points\n", scene.num_train, scene.num_test,
                scene.num_points);

    desplat::TrainingRunOptions options;
    options.data_dir = generate.out;
    options.out_dir = out / "model";
    options.overwrite = true;
    options.iterations = kSteps;
    options.threads = 2;
    options.checkpoint_every = 0;
    options.effects = "none";  // the static scene only, so no effects probe runs first
    const std::atomic<bool> stop{false};
    if (const int code = desplat::run_training(options, stop); code != 0)
      return fail("run_training returned " + std::to_string(code));

    // The static model as a 3DGS PLY: read back (the reader refuses NaN or Inf values).
    const desplat::GaussianSet model = desplat::read_gaussian_ply(options.out_dir / "point_cloud.ply");
    if (model.size() == 0) return fail("point_cloud.ply holds no Gaussians");

    std::ifstream metrics_file(options.out_dir / "metrics.json");
    const nlohmann::json metrics = nlohmann::json::parse(metrics_file);
    const int64_t steps = metrics.at("step").get<int64_t>();
    const double psnr = metrics.at("mean_psnr").get<double>();
    if (steps != kSteps)
      return fail("metrics.json: step " + std::to_string(steps) + ", expected " + std::to_string(kSteps));
    if (!std::isfinite(psnr) || psnr <= 0) return fail("metrics.json: mean_psnr " + std::to_string(psnr));
    // Training learned: the loss of the last steps is below that of the first ones.
    std::vector<double> losses;
    for (const nlohmann::json& entry : metrics.at("history"))
      if (entry.at("kind") == "training") losses.push_back(entry.at("loss").get<double>());
    if (losses.size() != static_cast<size_t>(kSteps))
      return fail("metrics.json: " + std::to_string(losses.size()) + " training entries in history, expected " +
                  std::to_string(kSteps));
    const auto mean_of_10 = [&](size_t from) {
      return std::accumulate(losses.begin() + from, losses.begin() + from + 10, 0.0) / 10;
    };
    const double first = mean_of_10(0), last = mean_of_10(losses.size() - 10);
    if (!(last < first)) return fail("the loss did not fall: " + std::to_string(first) + " → " + std::to_string(last));
    for (const char* file : {"config.json", "report.html"})
      if (!fs::is_regular_file(options.out_dir / file)) return fail(std::string(file) + " is missing");
    std::printf("trained %lld steps: %zu Gaussians, loss %.4f → %.4f, test PSNR %.2f dB\n",
                static_cast<long long>(steps), model.size(), first, last, psnr);
    return 0;
  } catch (const std::exception& e) {
    return fail(e.what());
  }
}
