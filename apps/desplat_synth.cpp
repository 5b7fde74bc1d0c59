// desplat_synth: writes a synthetic capture with known ground truth from a scene description
// (include/desplat/synth/synth.hpp; descriptions in data/synthetic/).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <optional>
#include <string>

#include "desplat/io/output_folder.hpp"
#include "desplat/synth/synth.hpp"

namespace {

namespace synth = desplat::synth;

const char* kDescription =
    "desplat_synth: a synthetic scene with known ground truth.\n"
    "\n"
    "Ray-traces a world of textured planes, boxes and spheres from the views of a scene\n"
    "description (JSON; see data/synthetic/README.md) and writes, under --out:\n"
    "  images/            every view as the camera recorded it (training views with the\n"
    "                     description's distractors, exposure changes and noise)\n"
    "  sparse/0/          binary COLMAP model: camera, poses, points3D with tracks\n"
    "  clean/             every view without distractors, exposure changes or noise\n"
    "  distractor_masks/  every training view: 255 where distractors cover the pixel\n"
    "  train_list.txt, test_list.txt, scene.json (the description with all defaults)\n"
    "Every 8th view (0000, 0008, ...) is a test view, as desplat_train's default split.\n";

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{kDescription, "desplat_synth"};
  std::string scene_file;
  synth::GenerateOptions options;
  std::optional<uint64_t> seed;
  bool quiet = false;
  app.add_option("--scene", scene_file, "Scene description (JSON), e.g. data/synthetic/bench.json")->required();
  app.add_option("--out", options.out, "Output folder (created if missing)")->required();
  app.add_option("--seed", seed, "Random seed, instead of the description's");
  app.add_flag("--overwrite", options.overwrite, "Replace an earlier generated scene in --out (only its files)");
  app.add_flag("--quiet,-q", quiet, "No progress lines (the summary is still printed)");
  CLI11_PARSE(app, argc, argv);

  if (!quiet)
    options.on_progress = [](const std::string& line) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    };
  try {
    desplat::check_output_folder("--out", options.out, {{"--scene", scene_file}});
    synth::Description d = synth::load_description(scene_file);
    if (seed) d = synth::apply_description(d, {{"seed", *seed}}, "--seed");
    const synth::GenerationReport r = synth::generate_scene(d, options);
    std::printf(
        "%s: %d training views (%zu with distractors), %d test views, %dx%d, %zu points, "
        "%zu observations; %.1f s (render %.1f s, points %.1f s, PNG %.1f s)\n",
        options.out.c_str(), r.num_train, r.cluttered_views.size(), r.num_test, d.camera.width, d.camera.height,
        r.num_points, r.num_observations, r.seconds, r.render_seconds, r.points_seconds, r.write_seconds);
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "desplat_synth: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
