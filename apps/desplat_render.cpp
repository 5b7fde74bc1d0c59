// desplat_render: renders views of a model trained by desplat_train.
#include <CLI/CLI.hpp>

#include <cstdio>

#include "desplat/jobs/render_run.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Render views of a trained desplat model (the --out folder of desplat_train) to PNG files."};
  desplat::RenderRunOptions o;
  app.add_option("--model", o.model_dir, "desplat_train's output folder")->required()->check(CLI::ExistingDirectory);
  app.add_option("--out", o.out_dir, "folder for one PNG per view")->required();
  app.add_option("--layer", o.layer,
                 "static | distractor | composite (the last two: training views of a DeSplat model only)")
      ->capture_default_str();
  app.add_option("--views", o.views, "test, train, all, or comma-separated image names")->capture_default_str();
  app.add_flag("--mask", o.mask, "also write <name>_mask.png, the distractor mask A_d > 0.5 (training views)");
  app.add_flag("--alpha", o.alpha, "write RGBA PNGs whose alpha is the layer's coverage");
  app.add_flag("--figure", o.figure,
               "also write <name>_row.png: truth | static | distractor | composite | mask (training views)");
  app.add_option("--appearance", o.appearance,
                 "a training view's name: render the static layer in that photo's exposure and colour "
                 "(models trained with --effects ...,appearance; default: the plain colours of point_cloud.ply)");
  app.add_option("--threads", o.threads, "OpenMP threads; 0 = all cores")->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);
  try {
    const int n = desplat::run_render(o);
    std::printf("wrote %d images to %s\n", n, o.out_dir.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "desplat_render: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
