// desplat_train's and desplat_render's settings as a careless user gives them: an empty
// effects list, a negative seed, a count in exponent notation, a JSON array, a run's own
// config.json passed back, a resume without the recorded --downscale, a damaged config.json.
// Each is one sentence naming the option or file, and a refused run leaves no output folder.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <iterator>

#include <nlohmann/json.hpp>

#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {
namespace fs = std::filesystem;

struct Outcome {
  int exit_code;
  std::string output;
};

Outcome run(const std::string& command) {
  const fs::path log = fs::temp_directory_path() / ("desplat_settings_cli_" + std::to_string(::getpid()) + ".log");
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  std::string text;
  {
    std::ifstream f(log);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  fs::remove(log);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
}

nlohmann::json read_json(const fs::path& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

class SettingsCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("desplat_settings_cli_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    write_scene_folder(root_ / "scene", synthetic_training_data(8, 64, 48, 5));
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }
  static std::string train(const fs::path& out) {
    return std::string(DESPLAT_TRAIN_BIN) + " --data " + (root_ / "scene").string() + " --out " + out.string() +
           " --threads 2 --checkpoint-every 0";
  }
  static inline fs::path root_;
};

// A refused command: exit 1 (or CLI11's 105), `message` in its output, and no output folder.
void expect_refused(const Outcome& r, const std::string& message, const fs::path& out) {
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_CONTAINS(r.output, message);
  EXPECT_EQ(r.output.find("json.exception"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out)) << "a refused run left " << out;
}

TEST_F(SettingsCli, AnEmptyEffectsListIsRefused) {
  const fs::path out = root_ / "empty_effects";
  expect_refused(run(train(out) + " --iterations 2 --effects ''"), "--effects is empty", out);
}

TEST_F(SettingsCli, NegativeSeedsAndExponentCountsAreRefusedWithTheRange) {
  const fs::path out = root_ / "bad_numbers";
  expect_refused(run(train(out) + " --iterations 2 --seed -1"),
                 "--seed: must be an integer in [0, 9223372036854775807] (got -1)", out);
  expect_refused(run(train(out) + " --iterations 1e12"),
                 "--iterations: must be an integer in [1, 9223372036854775807], written in digits (got '1e12')", out);
}

TEST_F(SettingsCli, ConfigMustBeAnObjectOrAFile) {
  const fs::path out = root_ / "bad_config";
  expect_refused(run(train(out) + " --iterations 2 --config '[1,2,3]'"), "--config text must be a JSON object", out);
  expect_refused(run(train(out) + " --iterations 2 --config " + (root_ / "absent.json").string()),
                 "is neither a JSON object of settings", out);
  expect_refused(run(train(out) + R"( --iterations 2 --config '{"num_downscales": 1.7}')"),
                 "--config text: config: num_downscales must be an integer in [0, 10] (got 1.7)", out);
  // The first check failed: the next run into the same folder needs no --overwrite.
  const Outcome next = run(train(out) + " --iterations 2 --effects none");
  EXPECT_EQ(next.exit_code, 0) << next.output;
}

// A run's whole config.json (as the README suggests) reproduces its settings.
TEST_F(SettingsCli, ARunsOwnConfigJsonIsAccepted) {
  const fs::path first = root_ / "first", second = root_ / "second";
  const Outcome a =
      run(train(first) + R"( --iterations 4 --effects distractors --config '{"densify": {"warmup": 7}}')");
  ASSERT_EQ(a.exit_code, 0) << a.output;
  const Outcome b =
      run(train(second) + " --iterations 3 --effects distractors --config " + (first / "config.json").string());
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_CONTAINS(b.output, "its \"train\" settings apply");
  nlohmann::json ta = read_json(first / "config.json")["train"], tb = read_json(second / "config.json")["train"];
  EXPECT_EQ(tb["iterations"], 3);  // the command line applies on top
  EXPECT_EQ(tb["densify"]["warmup"], 7);
  ta.erase("iterations"), tb.erase("iterations");
  EXPECT_EQ(ta, tb);
}

// --resume takes the downscale config.json records.
TEST_F(SettingsCli, ResumeTakesTheRecordedDownscale) {
  const fs::path out = root_ / "downscaled";
  const std::string first = train(out) + R"( --effects distractors --downscale 2 --config '{"num_downscales": 0}')";
  const Outcome a = run(first + " --iterations 3");
  ASSERT_EQ(a.exit_code, 0) << a.output;
  const Outcome b = run(train(out) + " --iterations 5 --resume");
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_CONTAINS(b.output, "at 32x24");
  EXPECT_CONTAINS(b.output, "resumed from");
  EXPECT_EQ(read_json(out / "config.json")["scene"]["downscale"], 2);
  // Naming another size is still refused.
  const Outcome c = run(train(out) + " --iterations 6 --resume --downscale 1");
  EXPECT_EQ(c.exit_code, 1) << c.output;
  EXPECT_CONTAINS(c.output, "--resume: the scene is not the one");
}

// desplat_render on a config.json that desplat_train did not write: one sentence naming the
// file, what is wrong and what to do.
TEST_F(SettingsCli, RenderNamesADamagedConfigJson) {
  const fs::path model = root_ / "model";
  const Outcome a = run(train(model) + " --iterations 2 --effects none");
  ASSERT_EQ(a.exit_code, 0) << a.output;
  const std::string render =
      std::string(DESPLAT_RENDER_BIN) + " --model " + model.string() + " --out " + (root_ / "renders").string();
  const fs::path config = model / "config.json";
  const nlohmann::json good = read_json(config);
  const auto expect_named = [&](const std::string& text, const std::string& message) {
    testing::spit(config, text);
    const Outcome r = run(render);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_CONTAINS(r.output, config.string());
    EXPECT_CONTAINS(r.output, message);
    EXPECT_CONTAINS(r.output, "train the model again");
    EXPECT_EQ(r.output.find("json.exception"), std::string::npos) << r.output;
  };
  nlohmann::json no_train = good;
  no_train.erase("train");
  expect_named(no_train.dump(), "has no \"train\" settings");
  nlohmann::json wrong_type = good;
  wrong_type["train"] = 5;
  expect_named(wrong_type.dump(), "\"train\" must be an object of settings (it is number)");
  expect_named("[1, 2]", "is not a desplat config.json (its top level is array, not an object)");
  nlohmann::json bad_scene = good;
  bad_scene["scene"]["downscale"] = "two";
  expect_named(bad_scene.dump(), "the scene recipe is damaged");
}

}  // namespace
}  // namespace desplat::test
