// desplat_train with the appearance and background models (docs/METHOD.md §10–11), and
// desplat_render drawing a training view in that photo's own look.
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

// desplat_render --appearance view_1.png of the model in `model` draws exactly the static
// column of view_1's training figure row; without --appearance (plain colours over the
// evaluation background) it draws another image, the negative control. Renders go under
// root/<tag>_look and root/<tag>_plain.
void expect_render_in_view_1s_own_look(const fs::path& model, const fs::path& root, const std::string& tag) {
  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + model.string();
  const fs::path look = root / (tag + "_look"), plain = root / (tag + "_plain");
  const Outcome ok = run(render + " --out " + look.string() + " --views view_1.png --appearance view_1.png");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const FloatImage single = read_image_rgb(look / "view_1.png");
  expect_static_column(read_image_rgb(model / "renders" / "train" / "view_1.png"), single);
  const Outcome other = run(render + " --out " + plain.string() + " --views view_1.png");
  ASSERT_EQ(other.exit_code, 0) << other.output;
  EXPECT_NE(read_image_rgb(plain / "view_1.png").pixels, single.pixels);
}

// A background model (docs/METHOD.md §11): the run says so, scores by the Photo Tourism
// protocol, and desplat_render --appearance shows a training view over that photo's own learned
// background, exactly as the training figure's static column does.
TEST_F(TrainApp, BackgroundModelRendersOverAPhotosOwnBackground) {
  const fs::path out = root_ / "sky";
  const Outcome r =
      run(train() + " --out " + out.string() + " --iterations 60 --threads 2 --effects distractors,background");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background model: embeddings of 32 per training image"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["protocol"], "per-image embeddings fitted on the left half, scored on the right half");
  EXPECT_EQ(metrics["mean_psnr_right_half"], metrics["mean_psnr"]);
  EXPECT_TRUE(metrics["median_step_seconds_full_resolution"].contains("background"));

  expect_render_in_view_1s_own_look(out, root_, "sky");
}

// Appearance and background together: the background reads the appearance embedding (the
// default, the authors' form), the checkpoint says so, and desplat_render --appearance draws
// the training figure's static column exactly, sky included.
TEST_F(TrainApp, SharedEmbeddingRendersAsTheTrainerDrewIt) {
  const fs::path out = root_ / "both";
  const Outcome r = run(train() + " --out " + out.string() +
                        " --iterations 60 --threads 2 --effects distractors,appearance,background");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json config;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["train"]["background"]["share_appearance_embedding"], true);
  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + out.string();
  const Outcome ok =
      run(render + " --out " + (root_ / "both_look").string() + " --views view_1.png --appearance view_1.png");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  expect_static_column(read_image_rgb(out / "renders" / "train" / "view_1.png"),
                       read_image_rgb(root_ / "both_look" / "view_1.png"));
}

// --effects distractors,appearance: the run says which protocol scored the test views, and
// desplat_render --appearance NAME (from the checkpoint) draws the static layer exactly as the
// trainer drew it in NAME's figure row (renders/train, the view's own embedding).
TEST_F(TrainApp, AppearanceModelRendersInAPhotosLookAndSaysItsProtocol) {
  const fs::path out = root_ / "appearance";
  const Outcome r =
      run(train() + " --out " + out.string() + " --iterations 60 --threads 2 --effects distractors,appearance");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("appearance model: embeddings of 32 per training image"), std::string::npos) << r.output;
  nlohmann::json metrics, config;
  std::ifstream(out / "metrics.json") >> metrics;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["run"]["effects"], "distractors,appearance");
  EXPECT_EQ(metrics["protocol"], "per-image embeddings fitted on the left half, scored on the right half");
  for (const auto& v : metrics["views"]) EXPECT_EQ(v["protocol"], metrics["protocol"]);

  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + out.string();
  expect_render_in_view_1s_own_look(out, root_, "appearance");

  const Outcome test_view = run(render + " --out " + (root_ / "look2").string() + " --appearance view_0.png");
  EXPECT_EQ(test_view.exit_code, 1);
  EXPECT_NE(test_view.output.find("'view_0.png' is not a training view"), std::string::npos) << test_view.output;
  // The default is --effects auto: this capture has one exposure and no sky, so appearance and
  // background stay off, and the transient probe decides distractors (its answer on this
  // cloud of small blobs over a void is not a fact about the scene: tests/test_transient_probe.cpp
  // checks answers). The decision, its evidence in the log, config.json and metrics.json, and
  // the model trained must agree.
  const Outcome plain = run(train() + " --out " + (root_ / "no_look").string() + " --iterations 5 --threads 2");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  EXPECT_NE(plain.output.find("--effects auto: probing for transients"), std::string::npos) << plain.output;
  nlohmann::json auto_config, auto_metrics;
  std::ifstream(root_ / "no_look" / "config.json") >> auto_config;
  const nlohmann::json& evidence = auto_config["run"]["effects_evidence"];
  const bool transients = evidence["transients"]["transients"];
  const std::string chosen = transients ? "distractors" : "none";
  EXPECT_NE(plain.output.find("--effects auto: " + chosen + "\n"), std::string::npos) << plain.output;
  EXPECT_EQ(auto_config["run"]["effects"], chosen);
  EXPECT_EQ(auto_config["run"]["effects_chosen_by"], "auto");
  ASSERT_EQ(evidence["reasons"].size(), 3u);
  EXPECT_EQ(evidence["reasons"][0].get<std::string>().rfind(transients ? "distractors on: " : "distractors off: ", 0),
            0u)
      << evidence["reasons"][0];
  EXPECT_EQ(evidence["transients"]["views"].size(), auto_config["scene"]["train_views"].size());
  std::ifstream(root_ / "no_look" / "metrics.json") >> auto_metrics;
  EXPECT_EQ(auto_metrics["effects"]["evidence"]["transients"], evidence["transients"]);
  EXPECT_EQ(auto_metrics["mode"], transients ? "desplat" : "static-only");
  // … and trains exactly the model that names that set.
  const Outcome named =
      run(train() + " --out " + (root_ / "named").string() + " --iterations 5 --threads 2 --effects " + chosen);
  ASSERT_EQ(named.exit_code, 0) << named.output;
  EXPECT_EQ(testing::slurp(root_ / "named" / "point_cloud.ply"), testing::slurp(root_ / "no_look" / "point_cloud.ply"));
  const Outcome none = run(std::string(DESPLAT_RENDER_BIN) + " --model " + (root_ / "no_look").string() + " --out " +
                           (root_ / "look3").string() + " --appearance view_1.png");
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_NE(none.output.find("was trained without an appearance or background model"), std::string::npos)
      << none.output;
  const Outcome resume =
      run(train() + " --out " + out.string() + " --iterations 80 --threads 2 --resume --effects distractors");
  EXPECT_EQ(resume.exit_code, 1);
  // The recorded settings are checked before the checkpoint is opened (restore_training_checkpoint's
  // own refusal is tested in test_appearance.cpp).
  EXPECT_NE(
      resume.output.find("changes 1 of them: appearance.enabled false (true in " + (out / "config.json").string()),
      std::string::npos)
      << resume.output;
}

}  // namespace
}  // namespace desplat::test
