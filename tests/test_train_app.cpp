// desplat_train and desplat_render as a user runs them, on a synthetic scene folder: every
// output, a reused folder, the static-only model, distractor-mask metrics, a run without test
// views, and bad input.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/sfm/subprocess.hpp"
#include "desplat/synth/synth.hpp"
#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"
#include "support/train_app.hpp"

namespace desplat::test {
namespace {

TEST_F(TrainApp, TrainsAndWritesEveryOutput) {
  const fs::path out = root_ / "out";
  // 200 distractors per view (the default density gives 16 on 64×48 images): enough that some
  // still cover their view after 120 steps, for the layer and mask checks below.
  const Outcome r = run(
      train() + " --out " + out.string() +
      " --iterations 120 --threads 2 --log-every 40 --eval-every 60 --distractors-per-view 200 --effects distractors");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("120/120"), std::string::npos) << r.output;  // plain progress lines in a pipe
  // 120 steps end inside the default resolution schedule (full resolution from step 6,000).
  EXPECT_NE(r.output.find("never trains at full resolution (the resolution schedule reaches it at step 6000 of 120)"),
            std::string::npos)
      << r.output;
  // … and before the default's distractor seeding (from step 3,000).
  EXPECT_NE(r.output.find("warning: distractor seeding starts at step 3000 (distractors.seed_after), after this "
                          "run's 120 steps"),
            std::string::npos)
      << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["step"], 120);
  int evaluations = 0, curve_points = 0;
  for (const auto& h : metrics["history"])
    evaluations += h["kind"] == "evaluation", curve_points += h["kind"] == "training";
  EXPECT_EQ(evaluations, 1);     // at step 60; the final one is the metrics' own
  EXPECT_EQ(curve_points, 120);  // the training curve: every step of a run this short
  EXPECT_GT(metrics["mean_psnr"].get<double>(), 15.0);
  const GaussianSet ply = read_gaussian_ply(out / "point_cloud.ply");
  EXPECT_EQ(ply.size(), metrics["gaussians"].get<size_t>());
  nlohmann::json config;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["train"]["iterations"], 120);
  EXPECT_EQ(config["train"]["lr"]["means"], 1.6e-4f);  // docs/METHOD.md defaults are written out

  // desplat_render re-renders the test views as the evaluation saw them.
  const fs::path renders = root_ / "renders";
  const Outcome rr = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + renders.string());
  ASSERT_EQ(rr.exit_code, 0) << rr.output;
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(out / "renders" / "test")) {
    const FloatImage side = read_image_rgb(entry.path());
    const FloatImage single = read_image_rgb(renders / entry.path().filename());
    ASSERT_EQ(side.width, 2 * single.width);
    for (int y = 0; y < single.height; ++y)
      for (int x = 0; x < single.width; ++x)
        for (int c = 0; c < 3; ++c)
          ASSERT_EQ(side.pixels[(size_t(y) * side.width + single.width + x) * 3 + c],
                    single.pixels[(size_t(y) * single.width + x) * 3 + c]);
    ++compared;
  }
  EXPECT_EQ(compared, 2);  // 16 views, every 8th held out
  // DeSplat is the default: every training view has a Fig. 2 row and its layers can be rendered.
  EXPECT_EQ(metrics["mode"], "desplat");
  EXPECT_EQ(metrics["cost"]["views_with_distractors"], 14);  // no refinement before step 500
  EXPECT_TRUE(fs::exists(out / "renders" / "train" / "view_1.png"));
  const fs::path layers = root_ / "layers";
  const Outcome lr = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + layers.string() +
                         " --layer distractor --views train --mask --alpha");
  ASSERT_EQ(lr.exit_code, 0) << lr.output;
  EXPECT_TRUE(fs::exists(layers / "view_1.png"));
  EXPECT_TRUE(fs::exists(layers / "view_1_mask.png"));
  EXPECT_FALSE(fs::exists(layers / "view_0.png"));  // a test view
  // --alpha writes straight RGBA: re-compositing it over the evaluation background gives the
  // plain layer image, and its alpha agrees with the mask (A_d > 0.5).
  const fs::path plain = root_ / "layers_plain";
  ASSERT_EQ(run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + plain.string() +
                " --layer distractor --views view_1.png")
                .exit_code,
            0);
  OIIO::ImageSpec raw_file;  // the file's own straight values, as a viewer sees them
  raw_file.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open((layers / "view_1.png").string(), &raw_file);
  ASSERT_TRUE(in);
  ASSERT_EQ(in->spec().nchannels, 4);
  std::vector<float> rgba(size_t(in->spec().width) * in->spec().height * 4);
  ASSERT_TRUE(in->read_image(0, 0, 0, 4, OIIO::TypeDesc::FLOAT, rgba.data()));
  in->close();
  const FloatImage shown = read_image_rgb(plain / "view_1.png");
  const FloatImage mask = read_image_rgb(layers / "view_1_mask.png");
  const std::vector<float> bg = config["train"]["eval_background"].get<std::vector<float>>();
  ASSERT_EQ(rgba.size() / 4, shown.pixels.size() / 3);
  int covered = 0;
  for (size_t p = 0; p < rgba.size() / 4; ++p) {
    const float a = rgba[4 * p + 3];
    EXPECT_EQ(a > 0.5f, mask.pixels[3 * p] > 0.5f) << p;
    covered += a > 0.5f;
    for (int c = 0; c < 3; ++c)  // 8-bit PNGs: a few quantization steps
      ASSERT_NEAR(rgba[4 * p + c] * a + (1 - a) * bg[c], shown.pixels[3 * p + c], 3.0 / 255) << p;
  }
  EXPECT_GT(covered, 0);  // 120 steps: the initial distractors still cover part of the view
  // Test views have no distractors: asking for that layer there is one clear error.
  const Outcome bad_layer = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " +
                                renders.string() + " --layer distractor");
  EXPECT_EQ(bad_layer.exit_code, 1);
  EXPECT_NE(bad_layer.output.find("view 'view_0.png' is not a training view"), std::string::npos) << bad_layer.output;
}

// A fresh run into a folder that holds an earlier run is refused (it would overwrite that
// model's checkpoint and leave its renders next to the new ones); --overwrite replaces
// exactly the run's outputs and leaves other files alone.
TEST_F(TrainApp, ReusedOutputFolderIsRefusedUnlessOverwritten) {
  const fs::path out = root_ / "reused";
  ASSERT_EQ(run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only").exit_code, 0);
  const std::string checkpoint = testing::slurp(out / "checkpoint.ckpt");
  ASSERT_FALSE(checkpoint.empty());
  std::ofstream(out / "renders" / "test" / "from_another_scene.png") << "stale";
  std::ofstream(out / "notes.txt") << "the user's";

  Outcome r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, out.string() + " already holds a training run's outputs");
  EXPECT_CONTAINS(r.output, "checkpoint.ckpt");
  EXPECT_CONTAINS(r.output, "--resume");
  EXPECT_CONTAINS(r.output, "--overwrite");
  EXPECT_EQ(testing::slurp(out / "checkpoint.ckpt"), checkpoint) << "the earlier model must be untouched";

  r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --resume --overwrite");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, "--resume and --overwrite contradict each other");

  r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only --overwrite --seed 9");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(out / "renders" / "test" / "from_another_scene.png"));
  EXPECT_TRUE(fs::exists(out / "notes.txt"));
  EXPECT_TRUE(fs::exists(out / "metrics.json"));
  EXPECT_NE(testing::slurp(out / "checkpoint.ckpt"), checkpoint);
}

TEST_F(TrainApp, StaticOnlyModelHasNoDistractorLayer) {
  const fs::path out = root_ / "static_only";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 30 --threads 2 --static-only");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["mode"], "static-only");
  EXPECT_EQ(metrics["cost"]["distractor_gaussians"], 0);
  // The Splatfacto baseline starts from every sparse point, whatever the default does.
  EXPECT_EQ(metrics["transient_points"]["action"], "keep");
  EXPECT_EQ(metrics["transient_points"]["points"], 0);
  const Outcome bad = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " +
                          (root_ / "so_renders").string() + " --views train --mask");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("--mask needs a DeSplat model"), std::string::npos) << bad.output;
}

// A scene with ground-truth masks: metrics.json scores every training view's distractor mask.
TEST_F(TrainApp, MetricsScoreDistractorMasksWhenTheSceneHasThem) {
  synth::GenerateOptions g;
  g.out = root_ / "masked_scene";
  const synth::GenerationReport scene = synth::generate_scene(
      synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_distractors.json"), g);
  for (const std::string mode : {"", " --static-only"}) {
    const fs::path out = root_ / ("masked" + std::to_string(mode.size()));
    const Outcome r = run(std::string(DESPLAT_TRAIN_BIN) + " --data " + g.out.string() + " --out " + out.string() +
                          " --iterations 20 --threads 2" + mode);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("distractor masks: mean IoU"), std::string::npos) << r.output;
    nlohmann::json metrics;
    std::ifstream(out / "metrics.json") >> metrics;
    const nlohmann::json& masks = metrics["distractor_masks"];
    ASSERT_EQ(masks["views"].size(), size_t(scene.num_train));
    EXPECT_EQ(masks["occluded_views"], scene.cluttered_views.size());
    for (const auto& v : masks["views"]) {
      const bool cluttered = std::count(scene.cluttered_views.begin(), scene.cluttered_views.end(), v["name"]) > 0;
      EXPECT_EQ(v["truth_fraction"].get<double>() > 0, cluttered) << v["name"];
      if (!mode.empty()) {
        EXPECT_EQ(v["predicted_fraction"], 0.0);  // static-only predicts no distractors
      }
    }
    if (!mode.empty()) {
      EXPECT_EQ(masks["mean_iou"], 0.0);
    }
  }
}

TEST_F(TrainApp, NoTestViewsIsSaidNotScoredAsZero) {
  const fs::path out = root_ / "all_train";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --split all-train");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no test views to score"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("test PSNR 0.00"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_TRUE(metrics["mean_psnr"].is_null());
  EXPECT_EQ(metrics["count"], 0);
}

TEST_F(TrainApp, BadInputGivesOneClearError) {
  Outcome r = run(std::string(DESPLAT_TRAIN_BIN) + " --data " + (root_ / "nope").string() + " --out " +
                  (root_ / "o1").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find((root_ / "nope").string()), std::string::npos) << r.output;
  const fs::path cfg = root_ / "bad.json";
  std::ofstream(cfg) << R"({"lr": {"meens": 0.1}})";
  r = run(train() + " --out " + (root_ / "o2").string() + " --config " + cfg.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("unknown setting 'lr.meens'"), std::string::npos) << r.output;
  r = run(train() + " --out " + (root_ / "o3").string() + " --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no checkpoint"), std::string::npos) << r.output;
  // A setting that would divide by zero, and options out of range: one line each, nothing trained.
  std::ofstream(cfg) << R"({"resolution_schedule": 0})";
  r = run(train() + " --out " + (root_ / "o4").string() + " --config " + cfg.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("resolution_schedule must be an integer in [1, 2147483647] (got 0)"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(root_ / "o4" / "checkpoint.ckpt"));
  // The same settings given as JSON text instead of a file, and a file that is not there.
  r = run(train() + " --out " + (root_ / "o4").string() + R"( --config '{"resolution_schedule": 0}')");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--config text: config: resolution_schedule must be an integer in [1, 2147483647] (got 0)"),
            std::string::npos)
      << r.output;
  r = run(train() + " --out " + (root_ / "o4").string() + R"( --config '{"seed": ')");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--config text is not valid JSON"), std::string::npos) << r.output;
  r = run(train() + " --out " + (root_ / "o4").string() + " --config " + (root_ / "absent.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find((root_ / "absent.json").string()), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(root_ / "o4" / "checkpoint.ckpt"));
  for (const auto& [option, message] :
       {std::pair{"--iterations 0", "--iterations: must be an integer in [1, 9223372036854775807] (got 0)"},
        {"--checkpoint-every -3", "--checkpoint-every: must be an integer in [0, 2147483647] (got -3)"},
        {"--eval-every -1", "--eval-every: must be an integer in [0, 2147483647] (got -1)"},
        {"--downscale 1000", "--downscale: must be an integer in [1, 64] (got 1000)"}}) {
    r = run(train() + " --out " + (root_ / "o5").string() + " " + option);
    EXPECT_NE(r.exit_code, 0) << option;
    EXPECT_NE(r.output.find(message), std::string::npos) << r.output;
  }
}

}  // namespace
}  // namespace desplat::test
