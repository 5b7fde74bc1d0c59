// A trained model folder reopens exactly the views it was trained on, for every split rule:
// desplat_train for a few steps, then desplat_render of every view. The expected train/test
// names are worked out here from each rule's definition (include/desplat/io/splits.hpp), and each
// rendered static layer must equal the render the training run itself wrote for that view.
// Also: --resume refuses a changed scene recipe, and a model still opens after its list file moved.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>

#include "desplat/io/image_io.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"
#include "support/temp_dir.hpp"

namespace desplat::test {
namespace {
namespace fs = std::filesystem;
using desplat::testing::TempDir;

struct Outcome {
  int exit_code;
  std::string output;
};

Outcome run(const std::string& command, const fs::path& log) {
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, desplat::testing::slurp(log)};
}

// A 12-view scene whose image names are `names` (+ ".png"), in that order around the orbit.
void write_named_scene(const fs::path& dir, const std::vector<std::string>& names) {
  TrainingData data = synthetic_training_data(int(names.size()), 64, 48, 5);
  std::vector<TrainView> views;
  for (auto* list : {&data.train, &data.test})
    for (TrainView& v : *list) views.push_back(std::move(v));
  // synthetic_training_data names views view_<k>; give view k the k-th name.
  for (TrainView& v : views) v.name = names.at(std::stoul(v.name.substr(5)));
  data.train = std::move(views);
  data.test.clear();
  write_scene_folder(dir, data);
}

// Columns [x0, x0 + w) of an image, as an image of their own.
FloatImage crop_columns(const FloatImage& img, int x0, int w) {
  FloatImage out{w, img.height, img.channels, {}};
  for (int y = 0; y < img.height; ++y)
    for (int x = x0; x < x0 + w; ++x)
      for (int c = 0; c < img.channels; ++c)
        out.pixels.push_back(img.pixels[(size_t(y) * img.width + x) * img.channels + c]);
  return out;
}

struct Case {
  std::string rule;
  std::vector<std::string> names;     // the scene's images, without extension
  std::string split_args;             // added to desplat_train (files are written by `prepare`)
  std::set<std::string> train, test;  // expected, from the rule's definition
  std::function<std::string(const fs::path&)> prepare = [](const fs::path&) { return std::string(); };
};

std::vector<std::string> numbered(const std::string& prefix, int n) {
  std::vector<std::string> out;
  for (int i = 0; i < n; ++i) out.push_back(prefix + (i < 10 ? "0" : "") + std::to_string(i));
  return out;
}

std::vector<Case> every_rule() {
  std::vector<Case> cases;
  const std::vector<std::string> plain = numbered("v", 12);
  {  // every-nth with 4: sorted by name, positions 0, 4, 8 are test views
    Case c{"every-nth", plain, "--split every-nth --test-every 4", {}, {}};
    for (int i = 0; i < 12; ++i) (i % 4 == 0 ? c.test : c.train).insert(plain[i]);
    cases.push_back(c);
  }
  {
    Case c{"all-train", plain, "--split all-train", {plain.begin(), plain.end()}, {}};
    cases.push_back(c);
  }
  {  // lists: both given, every image on neither list is unused
    Case c{"lists", plain, "", {"v01", "v02", "v05", "v06", "v09"}, {"v03", "v10"}};
    c.prepare = [](const fs::path& root) {
      std::ofstream(root / "train.txt") << "v01.png\n# a comment\nv02.png\nv05.png\n\nv06.png\nv09.png\n";
      std::ofstream(root / "test.txt") << "v03.png\nv10.png\n";
      return "--split lists --train-list " + (root / "train.txt").string() + " --test-list " +
             (root / "test.txt").string();
    };
    cases.push_back(c);
  }
  {  // RobustNeRF: clutter trains, extra tests, clean is unused
    std::vector<std::string> names;
    for (int i = 0; i < 6; ++i) names.push_back("1clutter00" + std::to_string(i));
    for (int i = 0; i < 3; ++i) names.push_back("1extra00" + std::to_string(i));
    for (int i = 0; i < 3; ++i) names.push_back("1clean00" + std::to_string(i));
    Case c{"robustnerf", names, "--split robustnerf", {}, {}};
    for (const std::string& n : names)
      if (n.find("clutter") != std::string::npos)
        c.train.insert(n);
      else if (n.find("extra") != std::string::npos)
        c.test.insert(n);
    cases.push_back(c);
  }
  {  // On-the-go: "extra" in the name tests, everything else trains
    std::vector<std::string> names = numbered("frame", 9);
    for (int i = 0; i < 3; ++i) names.push_back("extra" + std::to_string(i));
    Case c{"onthego", names, "--split onthego", {}, {}};
    for (const std::string& n : names) (n.find("extra") != std::string::npos ? c.test : c.train).insert(n);
    cases.push_back(c);
  }
  {  // Photo Tourism: the .tsv's split column; rows without id are skipped; unlisted images unused
    Case c{"phototourism", plain, "", {"v00", "v02", "v04", "v06", "v08"}, {"v01", "v03"}};
    c.prepare = [](const fs::path& root) {
      std::ofstream tsv(root / "scene.tsv");
      tsv << "filename\tid\tsplit\tdataset\n";
      for (const char* n : {"v00", "v02", "v04", "v06", "v08"}) tsv << n << ".png\t1\ttrain\tx\n";
      tsv << "v01.png\t2\ttest\tx\nv03.png\t3\ttest\tx\nv05.png\t\ttrain\tx\n";
      return "--split phototourism --tsv " + (root / "scene.tsv").string();
    };
    cases.push_back(c);
  }
  return cases;
}

class ModelFolderRoundTrip : public ::testing::TestWithParam<size_t> {};

TEST_P(ModelFolderRoundTrip, RenderReopensTheTrainedViews) {
  const Case c = every_rule().at(GetParam());
  SCOPED_TRACE("split rule " + c.rule);
  TempDir root("model_" + c.rule);
  write_named_scene(root / "scene", c.names);
  const std::string split_args = c.split_args + c.prepare(root.path());
  const fs::path model = root / "model", renders = root / "renders";
  const Outcome trained =
      run(std::string(DESPLAT_TRAIN_BIN) + " --data " + (root / "scene").string() + " --out " + model.string() +
              " --iterations 5 --threads 2 --downscale 1 --effects distractors " + split_args,
          root / "train.log");
  ASSERT_EQ(trained.exit_code, 0) << trained.output;
  // The recipe is what the model reopens from: list and .tsv files may move afterwards.
  fs::remove(root / "train.txt"), fs::remove(root / "test.txt"), fs::remove(root / "scene.tsv");

  const Outcome rendered = run(std::string(DESPLAT_RENDER_BIN) + " --model " + model.string() + " --out " +
                                   renders.string() + " --views all --layer static",
                               root / "render.log");
  ASSERT_EQ(rendered.exit_code, 0) << rendered.output;

  std::set<std::string> written;
  for (const auto& e : fs::directory_iterator(renders)) written.insert(e.path().stem().string());
  std::set<std::string> expected = c.train;
  expected.insert(c.test.begin(), c.test.end());
  EXPECT_EQ(written, expected);

  const ModelFolder::Config config = ModelFolder(model).read_config();
  std::vector<std::string> train, test;
  for (const std::string& n : config.scene.train_views) train.push_back(fs::path(n).stem().string());
  for (const std::string& n : config.scene.test_views) test.push_back(fs::path(n).stem().string());
  EXPECT_EQ(std::set<std::string>(train.begin(), train.end()), c.train);
  EXPECT_EQ(std::set<std::string>(test.begin(), test.end()), c.test);

  // Each view's static render equals the one training wrote: the right half of a test view's
  // "truth | render", the second panel of a training view's "truth | static | …" row.
  for (const std::string& name : expected) {
    const FloatImage ours = read_image_rgb(renders / (name + ".png"));
    const bool is_test = c.test.count(name) > 0;
    const FloatImage row = read_image_rgb(model / "renders" / (is_test ? "test" : "train") / (name + ".png"));
    const FloatImage theirs = crop_columns(row, ours.width, ours.width);  // the second panel in both
    ASSERT_EQ(theirs.height, ours.height) << name;
    EXPECT_EQ(theirs.pixels, ours.pixels) << name;
  }
}

INSTANTIATE_TEST_SUITE_P(EverySplitRule, ModelFolderRoundTrip, ::testing::Range<size_t>(0, 6),
                         [](const ::testing::TestParamInfo<size_t>& param) {
                           std::string n = every_rule().at(param.param).rule;
                           n.erase(std::remove(n.begin(), n.end(), '-'), n.end());
                           return n;
                         });

TEST(ModelFolder, ResumeRefusesAChangedSceneRecipe) {
  TempDir root("model_resume");
  write_named_scene(root / "scene", numbered("v", 12));
  const std::string train = std::string(DESPLAT_TRAIN_BIN) + " --data " + (root / "scene").string() + " --out " +
                            (root / "model").string() + " --threads 2 ";
  ASSERT_EQ(run(train + "--iterations 3", root / "a.log").exit_code, 0);
  Outcome r = run(train + "--iterations 6 --resume --downscale 2", root / "b.log");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, "--downscale was 1, now 2");
  r = run(train + "--iterations 6 --resume --test-every 3", root / "c.log");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, "the training views differ");
  r = run(train + "--iterations 6 --resume", root / "d.log");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(ModelFolder, RecipeJsonRoundTripsEveryField) {
  SceneRecipe r;
  r.data_dir = "/data/scene";
  r.downscale = 4;
  r.split.rule = SplitRule::RobustNeRF;
  r.split.clutter_ratio = 0.25;
  r.train_views = {"b.png", "a.png"};
  r.test_views = {"c.png"};
  const SceneRecipe back = SceneRecipe::from_json(r.to_json());
  EXPECT_EQ(back.difference(r), "");
  EXPECT_EQ(back.split.rule, SplitRule::RobustNeRF);
  EXPECT_EQ(back.split.clutter_ratio, 0.25);
  EXPECT_EQ(back.train_views, r.train_views);  // order kept
  nlohmann::json broken = r.to_json();
  broken["split"]["rule"] = "sometimes";
  EXPECT_CONTAINS(desplat::testing::error_of<std::invalid_argument>([&] { SceneRecipe::from_json(broken); }),
                  "unknown split rule 'sometimes'");
}

}  // namespace
}  // namespace desplat::test
