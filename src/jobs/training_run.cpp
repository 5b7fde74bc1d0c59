// desplat_train's job as a short sequence: check the output folder, request the settings,
// load the inputs, resolve the settings, then train, evaluate and write. Nothing is written
// to the output folder before every check has passed (SfM on --images writes <out>/sfm).
#include "desplat/jobs/training_run.hpp"

#include "desplat/io/output_folder.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "desplat/jobs/model_folder.hpp"
#include "desplat/jobs/run_settings.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "jobs/training_steps.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// A fresh run refuses a folder holding an earlier run's outputs unless --overwrite (which
// removes them only once every check has passed: prepare_output_folder).
void refuse_earlier_outputs(const TrainingRunOptions& opt) {
  if (opt.resume && opt.overwrite) throw std::invalid_argument("--resume and --overwrite contradict each other");
  if (opt.resume || opt.overwrite) return;
  const std::vector<fs::path> outputs = ModelFolder(opt.out_dir).existing_training_outputs();
  if (outputs.empty()) return;
  std::string names;
  for (const fs::path& p : outputs) names += (names.empty() ? "" : ", ") + p.filename().string();
  throw std::invalid_argument(opt.out_dir.string() + " already holds a training run's outputs (" + names +
                              "): continue it with --resume, replace them with --overwrite, or choose another --out");
}

void prepare_output_folder(const TrainingRunOptions& opt) {
  if (opt.overwrite) ModelFolder(opt.out_dir).remove_training_outputs();
  fs::create_directories(opt.out_dir);
}

// What this run trains, on stdout, with the warnings a short run needs.
void describe_run(const TrainConfig& config, const RunInputs& inputs) {
  const TrainingData& data = inputs.data;
  const Scene& scene = inputs.scene;
  const fs::path& data_dir = inputs.data_dir;
  std::printf("scene %s: %zu training and %zu test views at %dx%d, %zu points\n", data_dir.c_str(), data.train.size(),
              data.test.size(), data.train.empty() ? 0 : data.train[0].camera.width,
              data.train.empty() ? 0 : data.train[0].camera.height, data.points.size());
  if (!scene.masks_dir.empty()) {
    const auto masked = std::count_if(scene.views.begin(), scene.views.end(),
                                      [](const SceneView& v) { return !v.user_mask_path.empty(); });
    std::printf("masks from %s for %ld of %zu views: their black pixels are ignored in training and metrics\n",
                scene.masks_dir.c_str(), static_cast<long>(masked), scene.views.size());
  }
  if (config.distractors.enabled)
    std::printf("DeSplat: %d distractor Gaussians per training view%s%s\n",
                data.train.empty() ? 0 : distractor_count_for(data.train[0].camera, config.distractors),
                config.distractors.density_control ? "" : ", no distractor density control",
                config.distractors.regularize ? "" : ", no opacity regularizers");
  else
    std::printf("static-only (Splatfacto baseline)\n");
  // Splatfacto's resolution schedule assumes 30k steps; a short run would silently end on
  // downscaled images and score poorly at full resolution.
  const int64_t full_resolution_from = config.full_resolution_from();
  if (full_resolution_from >= config.iterations)
    std::printf(
        "warning: this run never trains at full resolution (the resolution schedule reaches it at step "
        "%lld of %lld); add {\"num_downscales\": 0} to --config or train longer\n",
        (long long)full_resolution_from, (long long)config.iterations);
  // The default waits for step 3,000 before seeding distractors (docs/METHOD.md §7): a
  // shorter run never grows a buffer onto an occluder its initial distractors missed.
  const DistractorSettings& ds = config.distractors;
  if (config.distractors.enabled && (ds.seed_uncovered || ds.reseed_starved_views) &&
      ds.seed_after >= config.iterations)
    std::printf(
        "warning: distractor seeding starts at step %d (distractors.seed_after), after this run's %lld steps; "
        "for a run this short use --preset fast, or add {\"distractors\": {\"seed_after\": 0}} to --config\n",
        ds.seed_after, (long long)config.iterations);

  if (config.appearance.enabled)
    std::printf(
        "appearance model: embeddings of %d per training image and %d per Gaussian, MLP %d x %d; test views are "
        "scored by the Photo Tourism protocol (embedding fitted on the left half, %d steps from %s; scored on the "
        "right)\n",
        config.appearance.image_dim, config.appearance.feature_dim(), config.appearance.hidden_layers,
        config.appearance.hidden_width, config.appearance.test_steps,
        config.appearance.test_start_from_best_look ? "the training look that fits it best" : "the mean look");
  if (config.background.enabled)
    std::printf(
        "background model: embeddings of %d per training image, MLP %d x %d to spherical harmonics of degree %d; "
        "test views are scored by the Photo Tourism protocol (embeddings fitted on the left half, %d steps from "
        "%s)\n",
        config.background.image_dim, config.background.hidden_layers, config.background.hidden_width,
        config.background.sh_degree, config.appearance.test_steps,
        config.appearance.test_start_from_best_look ? "the training look that fits it best" : "the mean look");
}

// After the Trainer is built: what initialization did with transient points and the camera path.
void describe_trainer(const Trainer& trainer) {
  const TrainConfig& config = trainer.config();
  const TrainingData& data = trainer.data();
  if (config.transient_points.action != TransientPointAction::keep)
    std::printf("transient sparse points (%s): %lld of %zu, %lld distractors seeded from them\n",
                to_string(config.transient_points.action).c_str(), (long long)trainer.transient_point_count,
                data.points.size(), (long long)trainer.transient_seeded);
  if (const CameraPath& path = trainer.camera_path(); !path.empty())
    std::printf(
        "camera path: %zu segments between consecutive training views (%zu longer than %.2f x the median "
        "scene depth skipped); static Gaussians within %.4f world units of it, or in a blind gap (within "
        "%.2f x a step of it, in front, in neither photo) are culled\n",
        path.from.size(), path.skipped_segments, double(config.densify.camera_path.max_segment), path.radius,
        path.blind_gap);
}

}  // namespace

int run_training(const TrainingRunOptions& opt, const std::atomic<bool>& stop_requested, Communicator* comm) {
  const int rank = comm ? comm->rank() : 0, ranks = comm ? comm->size() : 1;
  if (ranks > 1 && !opt.images_dir.empty())
    throw std::invalid_argument(
        "--images runs COLMAP, which a job of several ranks does not do: place the photos first with "
        "desplat_sfm --images " +
        opt.images_dir.string() +
        " --out SCENE (or desplat_train --images in one process), then train with mpirun "
        "or srun and --data SCENE");
  check_output_folder("--out", opt.out_dir,
                      {{"--data", opt.data_dir}, {"--images", opt.images_dir}, {"--masks", opt.masks_dir}});
  refuse_earlier_outputs(opt);
  const RequestedSettings requested = request_settings(opt);
  const RunInputs inputs = load_run_inputs(opt, rank, ranks);
  const ModelFolder model(opt.out_dir);
  const std::optional<ResolvedSettings> settings =
      resolve_settings(requested, opt, inputs.data, inputs.resumed ? &*inputs.resumed : nullptr,
                       model.config_path().string(), stop_requested, comm);
  if (!settings) {
    std::printf("interrupted during the transient probe, before training started: no checkpoint was written\n");
    return 130;
  }
  describe_run(settings->config, inputs);
  if (ranks > 1)
    std::printf("%d ranks (%s): each holds the photos of about 1/%d of the views; global batch %d\n", ranks,
                comm->kind(), ranks, settings->config.batch);
  Trainer trainer(inputs.data, settings->config, comm);  // its own checks (image sizes) come first too
  // Rank 0 alone writes the output folder; the others wait until it is in place.
  if (rank == 0) {
    prepare_output_folder(opt);
    // The trainer's configuration is the effective one (e.g. a static-only model keeps every
    // sparse point): that is what config.json records.
    model.write_config({trainer.config(), inputs.recipe, settings->run, {}});
  }
  if (comm) comm->barrier();
  describe_trainer(trainer);
  // One checkpoint for the job: every view's state gathered onto rank 0, which writes it.
  auto write_checkpoint = [&] {
    trainer.gather_to_root();
    if (rank == 0) model.write_checkpoint(trainer, {{"run", settings->run}});
  };
  auto save = [&] {
    write_checkpoint();
    trainer.keep_own_share();
  };
  if (opt.resume) {
    restore_training_checkpoint(trainer, model.read_checkpoint());
    trainer.keep_own_share();
    std::printf("resumed from %s at step %lld\n", model.checkpoint_path().c_str(), (long long)trainer.current_step());
  }
  const TrainingRecord record = train_to_end(trainer, opt, inputs.scene, save, stop_requested);
  if (record.interrupted) return 130;
  write_checkpoint();  // rank 0 keeps every view's state for the outputs
  write_training_outputs(trainer, opt, inputs, *settings, record);
  return 0;
}

}  // namespace desplat
