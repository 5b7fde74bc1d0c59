// report.html's "effects modelled" row states the effects the run recorded (metrics.json's
// effects.chosen), whether the command line named them or --effects auto chose them, on a
// synthetic capture with open sky above the scene (desplat_synth's generator).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "desplat/synth/synth.hpp"
#include "support/expect.hpp"
#include "support/temp_dir.hpp"

namespace desplat::test {
namespace {
namespace fs = std::filesystem;

// desplat_train on `data` into `out`, its exit status and output.
std::pair<int, std::string> train(const fs::path& data, const fs::path& out, const std::string& flags) {
  const fs::path log = out.string() + ".log";
  const std::string command = std::string(DESPLAT_TRAIN_BIN) + " --data " + data.string() + " --out " + out.string() +
                              " --iterations 20 --threads 2 " + flags + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, testing::slurp(log)};
}

// The text of the report's "effects modelled" row.
std::string effects_row(const fs::path& report) {
  const std::string html = testing::slurp(report);
  const std::string start = "<tr><th>effects modelled</th><td>";
  const size_t at = html.find(start);
  if (at == std::string::npos) return "(no effects row)";
  const size_t from = at + start.size();
  return html.substr(from, html.find("</td>", from) - from);
}

nlohmann::json read_json(const fs::path& file) {
  nlohmann::json j;
  std::ifstream(file) >> j;
  return j;
}

class ReportEffects : public ::testing::Test {
 protected:
  // A small capture of the bench scene from low cameras, open sky filling the top of the
  // frames, no distractors and one exposure for every photo.
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir("report_effects");
    testing::spit(*dir_ / "scene.json", R"({"base": ")" +
                                            (fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/bench.json").string() +
                                            R"(", "camera.width": 160, "camera.height": 120, "views.count": 24,
                         "distractors.clutter_ratio": 0, "sky.enabled": true, "views.height": 1.0,
                         "views.target": [0, 0, 0.5]})");
    synth::GenerateOptions g;
    g.out = *dir_ / "capture";
    synth::generate_scene(synth::load_description(*dir_ / "scene.json"), g);
  }
  static void TearDownTestSuite() { delete dir_; }
  static inline testing::TempDir* dir_ = nullptr;
};

TEST_F(ReportEffects, NamedEffectsAreTheOnesTheRowStates) {
  const fs::path out = *dir_ / "appearance";
  const auto [status, log] = train(*dir_ / "capture", out, "--effects appearance");
  ASSERT_EQ(status, 0) << log;
  ASSERT_EQ(read_json(out / "metrics.json")["effects"]["chosen"], "appearance");
  EXPECT_EQ(effects_row(out / "report.html"),
            "static scene + per-image appearance (exposure and colour); distractors and background are not modelled");
}

TEST_F(ReportEffects, EffectsAutoChoseAreTheOnesTheRowStates) {
  const fs::path out = *dir_ / "auto";
  const auto [status, log] = train(*dir_ / "capture", out, "--effects auto");
  ASSERT_EQ(status, 0) << log;
  const nlohmann::json effects = read_json(out / "metrics.json")["effects"];
  ASSERT_EQ(effects["by"], "auto");
  const std::string chosen = effects["chosen"];
  // The open sky is what auto reads for the background (docs/METHOD.md §10, choosing the effects).
  ASSERT_NE(chosen.find("background"), std::string::npos) << log;
  const bool distractors = chosen.find("distractors") != std::string::npos;
  const bool appearance = chosen.find("appearance") != std::string::npos;
  std::string expected = "static scene";
  if (distractors) expected += " + per-view distractors (DeSplat)";
  if (appearance) expected += " + per-image appearance (exposure and colour)";
  expected += " + learned background (a colour per ray direction)";
  if (!distractors && !appearance)
    expected += "; distractors and appearance are not modelled";
  else if (!distractors)
    expected += "; distractors are not modelled";
  else if (!appearance)
    expected += "; appearance is not modelled";
  EXPECT_EQ(effects_row(out / "report.html"), expected + " (chosen by --effects auto)") << "chosen: " << chosen;
}

}  // namespace
}  // namespace desplat::test
