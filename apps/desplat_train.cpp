// desplat_train: trains a Gaussian splatting model from a COLMAP capture (or a folder
// of photos, via COLMAP) on the CPU. Options only; the job is desplat::run_training.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <memory>
#include <new>

#include "desplat/comm/communicator.hpp"

#include "desplat/jobs/training_run.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "range_checks.hpp"
#include "split_options.hpp"
#include "stop_signal.hpp"

int main(int argc, char** argv) {
  // Under mpirun or srun one rank of a data-parallel job (docs/METHOD.md §6, ranks), else one
  // process. Opened first: MPI may take its own arguments out of argv.
  std::unique_ptr<desplat::Communicator> comm;
  try {
    comm = desplat::open_communicator(&argc, &argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "desplat_train: error: %s\n", e.what());
    return 2;
  }
  // Only rank 0 prints progress; every rank's warnings and errors go to stderr.
  if (comm->rank() != 0 && !std::freopen("/dev/null", "w", stdout)) return 1;
  CLI::App app{
      "Train a 3D Gaussian Splatting model on the CPU.\n"
      "Input: --data DIR with images/ and sparse/0/ (a COLMAP model), or --images DIR with photos only\n"
      "(COLMAP then reconstructs the cameras). Outputs go to --out (see README: config.json,\n"
      "checkpoint.ckpt, metrics.json, renders/test/, renders/train/, point_cloud.ply). Ctrl-C writes a\n"
      "checkpoint\n"
      "and exits; --resume continues from it."};
  desplat::TrainingRunOptions o;
  auto* data = app.add_option("--data", o.data_dir, "scene folder with images/ and sparse/0/");
  auto* images = app.add_option("--images", o.images_dir, "folder of photos without a model: run COLMAP SfM first");
  data->excludes(images);
  app.add_option("--masks", o.masks_dir,
                 "folder of masks, one PNG per photo named like it (0002.jpg.png or 0002.png), black = ignore "
                 "the pixel in training and metrics (default: the scene's masks/ folder when it exists)");
  app.add_option("--out", o.out_dir, "output folder")->required();
  app.add_option("--config", o.config,
                 "training settings as JSON (docs/CONFIG.md lists them): a file, the JSON itself "
                 "(--config '{\"num_downscales\": 0}'), or a run's config.json (its \"train\" settings apply)");
  app.add_option("--preset", o.preset,
                 "starting settings: fast (a 3,000-step preview), default (what measures best, 30,000 steps) "
                 "or paper (the authors' exact behaviour); --config and --iterations apply on top. Default: default "
                 "(with --resume: the settings the model was trained with)")
      ->check(CLI::IsMember(desplat::preset_names()));
  app.add_option("--iterations", o.iterations, "training views seen: steps at --batch 1 (default 30000)")
      ->check(desplat::apps::integer_in(1, INT64_MAX));
  app.add_option("--batch", o.batch,
                 "training views per optimizer step (default 1): their static gradients are summed into one "
                 "Adam step with the rates x sqrt(batch) and the betas ^ batch; --iterations and every schedule "
                 "count views (docs/METHOD.md §6, batches)")
      ->check(desplat::apps::integer_in(1, 1024));
  app.add_option("--seed", o.seed, "random seed (default 0)")->check(desplat::apps::integer_in(0, INT64_MAX));
  app.add_option("--threads", o.threads, "OpenMP threads; 0 = all cores")->check(desplat::apps::integer_in(0, 4096));
  app.add_flag("--static-only", o.static_only,
               "static Gaussians only: the Splatfacto baseline (default: DeSplat, with per-view distractors)");
  app.add_option("--effects", o.effects,
                 "what to model beyond the static scene: auto (the default: distractors, appearance when the "
                 "SfM tracks show the photos' exposure or colour balance differ, background when open sky fills "
                 "the top of the frames), none, or a comma-separated list of distractors (per-view distractor "
                 "Gaussians), appearance (per-image exposure and colour; test views are then scored by the "
                 "Photo Tourism protocol) and background (a learned colour per ray direction behind the scene)");
  app.add_option("--distractors-per-view", o.distractors_per_view,
                 "exactly N initial distractor Gaussians per training view (default: 1000 per 504x378 "
                 "pixels, the paper's density, scaled with the training image size)")
      ->check(desplat::apps::integer_in(0, 10000000));
  app.add_flag("--no-distractor-density", o.no_distractor_density, "ablation: never split/duplicate/cull distractors");
  app.add_flag("--no-regularization", o.no_regularization, "ablation: drop the two opacity regularizers");
  app.add_flag("--resume", o.resume,
               "continue from --out/checkpoint.ckpt with the settings in --out/config.json; only --iterations "
               "(to train longer) and --threads may change them");
  app.add_flag("--overwrite", o.overwrite,
               "replace an earlier run's outputs in --out (config.json, checkpoint.ckpt, metrics.json, "
               "point_cloud.ply, renders/); without it such a folder is refused");
  app.add_option("--downscale", o.downscale,
                 "train on images downscaled by this factor (uses images_N/ if present; default 1, with --resume the "
                 "model's)")
      ->check(desplat::apps::integer_in(1, 64));
  app.add_flag_callback(
      "--print-settings-reference",
      [] {
        std::fputs(desplat::settings_reference_markdown().c_str(), stdout);
        throw CLI::Success();
      },
      "print the reference of every training setting (docs/CONFIG.md) and exit");
  std::string split_rule = "every-nth";
  desplat::apps::add_split_options(app, o.split, split_rule);
  app.add_option("--eval-every", o.eval_every, "evaluate test views every N steps (0: only at the end)")
      ->check(desplat::apps::integer_in(0, INT32_MAX))
      ->capture_default_str();
  app.add_option("--checkpoint-every", o.checkpoint_every, "write a checkpoint every N steps (0: only at the end)")
      ->check(desplat::apps::integer_in(0, INT32_MAX))
      ->capture_default_str();
  app.add_option("--log-every", o.log_every, "when not on a terminal, print a progress line every N steps")
      ->check(desplat::apps::integer_in(1, INT32_MAX))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (o.data_dir.empty() && o.images_dir.empty()) {
    std::fprintf(stderr, "desplat_train: give --data DIR (COLMAP scene) or --images DIR (photos)\n");
    return 2;
  }
  const std::atomic<bool>& stop = desplat_apps::stop_on_signals();
  try {
    o.split.rule = desplat::split_rule_from_name(split_rule);
    return desplat::run_training(o, stop, comm.get());
  } catch (const std::bad_alloc&) {
    // A rank out of memory ends the whole job (the others would wait for it forever).
    if (comm->size() > 1) comm->abort("desplat_train: error: out of memory; use more ranks or a larger --downscale");
    std::fprintf(stderr, "desplat_train: error: out of memory; use a larger --downscale\n");
    return 1;
  } catch (const std::exception& e) {
    if (comm->size() > 1) comm->abort(std::string("desplat_train: error: ") + e.what());
    std::fprintf(stderr, "desplat_train: error: %s\n", e.what());
    return 1;
  }
}
