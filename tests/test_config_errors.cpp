// Every setting of config.json out of its range is one error naming the setting, what is
// allowed and the value (never a SIGFPE on a zero interval, never a silently useless rate or
// size). The defaults and both presets are valid.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <limits>
#include <set>

#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "support/expect.hpp"

namespace desplat {
namespace {

std::string error_for(const nlohmann::json& j) {
  return testing::error_of<std::invalid_argument>([&] { config_from_json(j); });
}

TEST(ConfigErrors, DefaultsAndPresetsAreValid) {
  for (const std::string& name : preset_names()) EXPECT_NO_THROW(validate_config(preset_config(name))) << name;
  EXPECT_NO_THROW(config_from_json(config_to_json(TrainConfig{})));  // a run's own config.json reads back
}

TEST(ConfigErrors, ZeroIntervalsThatWouldDivideByZero) {
  EXPECT_CONTAINS(error_for({{"resolution_schedule", 0}}),
                  "config: resolution_schedule must be an integer in [1, 2147483647] (got 0)");
  EXPECT_CONTAINS(error_for({{"sh_degree_interval", 0}}),
                  "config: sh_degree_interval must be an integer in [1, 2147483647] (got 0)");
  EXPECT_CONTAINS(error_for({{"densify", {{"refine_every", 0}, {"warmup", 0}}}}),
                  "config: densify.refine_every must be an integer in [1, 2147483647] (got 0)");
  EXPECT_CONTAINS(error_for({{"densify", {{"reset_alpha_every", 0}}}}),
                  "densify.reset_alpha_every must be an integer in [1, 2147483647]");
  EXPECT_CONTAINS(error_for({{"means_lr_decay_steps", 0}}), "means_lr_decay_steps must be an integer in [1, 10^18]");
}

TEST(ConfigErrors, UselessRatesAndSizes) {
  EXPECT_CONTAINS(error_for({{"lr", {{"means", 0}}}}), "config: lr.means must be a number in (0, 10^18] (got 0)");
  EXPECT_CONTAINS(error_for({{"lr", {{"means", -1e-4}}}}), "lr.means must be a number in (0, 10^18] (got -0.0001)");
  EXPECT_CONTAINS(error_for({{"means_lr_final", -1e-6}}), "means_lr_final must be a number in (0, 10^18]");
  EXPECT_CONTAINS(error_for({{"lr", {{"quats", -1}}}}),
                  "lr.quats must be a number in [0, 10^18] (0 freezes the group) (got -1)");
  EXPECT_CONTAINS(error_for({{"ssim_lambda", 5}}), "config: ssim_lambda must be a number in [0, 1] (got 5)");
  EXPECT_CONTAINS(error_for({{"num_downscales", -3}}), "config: num_downscales must be an integer in [0, 10] (got -3)");
  EXPECT_CONTAINS(error_for({{"random_init_points", 0}}),
                  "config: random_init_points must be an integer in [1, 100000000] (got 0)");
  EXPECT_CONTAINS(error_for({{"distractors", {{"init_opacity", 1.0}}}}),
                  "distractors.init_opacity must be a number in (0, 0.999]");
  EXPECT_CONTAINS(error_for({{"eval_background", {0.1, 2.0, 0.2}}}),
                  "eval_background must be three numbers, each in [0, 1] (got 2.0)");
  EXPECT_CONTAINS(error_for({{"threads", -2}}), "threads must be an integer in [0, 4096] (0: all cores) (got -2)");
  EXPECT_CONTAINS(error_for({{"background", {{"sh_degree", 5}}}}),
                  "config: background.sh_degree must be an integer in [0, 4] (got 5)");
  EXPECT_CONTAINS(error_for({{"background", {{"hidden_layers", 0}}}}),
                  "background.hidden_layers must be an integer in [1, 16] (got 0)");
  EXPECT_CONTAINS(error_for({{"background", {{"explained_share", 1.0}}}}),
                  "background.explained_share must be a number in [0, 1)");
  EXPECT_CONTAINS(error_for({{"background", {{"lr", {{"mlp", -1}}}}}}),
                  "background.lr.mlp must be a number in [0, 10^18]");
  EXPECT_CONTAINS(
      error_for({{"distractors", {{"min_blend_weight", -1}}}}),
      "config: distractors.min_blend_weight must be a number in [0, 10^18] (0 turns the rule off) (got -1)");
  // Zero where zero is meaningful stays allowed: a frozen group, no regularizer, no cap.
  EXPECT_NO_THROW(config_from_json(
      {{"lr", {{"sh_rest", 0}}}, {"distractors", {{"lambda_static", 0}, {"pixels_per_distractor", 0}}}}));
}

// The pixel-loop instruction set by name: unknown names and paths this CPU lacks are refused.
TEST(ConfigErrors, KernelIsaMustBeAKnownPathThisCpuRuns) {
  EXPECT_CONTAINS(error_for({{"kernel_isa", "sse9"}}),
                  "config: kernel_isa must be auto, portable, avx2 or avx512 (got \"sse9\")");
  EXPECT_CONTAINS(error_for({{"kernel_isa", 2}}), "config: kernel_isa must be auto, portable, avx2 or avx512 (got 2)");
  EXPECT_EQ(config_from_json({{"kernel_isa", "portable"}}).kernel_isa, KernelIsa::Portable);
  EXPECT_EQ(config_to_json(TrainConfig{})["kernel_isa"], "auto");
  for (KernelIsa isa : {KernelIsa::Avx2, KernelIsa::Avx512}) {
    const nlohmann::json j = {{"kernel_isa", kernel_isa_name(isa)}};
    if (cpu_supports(isa))
      EXPECT_EQ(config_from_json(j).kernel_isa, isa);
    else
      EXPECT_CONTAINS(error_for(j), std::string("config: kernel_isa ") + kernel_isa_name(isa) +
                                        " is not supported by this CPU (or this build); use auto");
  }
}

TEST(ConfigErrors, OwnedPixelPullSettingsAreCheckedAndRead) {
  EXPECT_CONTAINS(error_for({{"distractors", {{"lambda_owned", -0.1}}}}),
                  "distractors.lambda_owned must be a number in [0, 10^18]");
  EXPECT_CONTAINS(error_for({{"distractors", {{"owned_after", -1}}}}),
                  "distractors.owned_after must be an integer in [0, 2147483647]");
  const TrainConfig c = config_from_json({{"distractors", {{"lambda_owned", 0.5}, {"owned_after", 100}}}});
  EXPECT_EQ(c.distractors.lambda_owned, 0.5f);
  EXPECT_EQ(c.distractors.owned_after, 100);
}

TEST(ConfigErrors, OccluderColourPriorWeightIsCheckedAndRead) {
  EXPECT_CONTAINS(error_for({{"distractors", {{"lambda_occluder_colour", -0.1}}}}),
                  "distractors.lambda_occluder_colour must be a number in [0, 10^18]");
  EXPECT_EQ(config_from_json({{"distractors", {{"lambda_occluder_colour", 0.4}}}}).distractors.lambda_occluder_colour,
            0.4f);
}

TEST(ConfigErrors, NonFiniteValuesAreRefusedWhateverTheSetting) {
  TrainConfig c;
  c.densify.grad_threshold = std::numeric_limits<float>::quiet_NaN();
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { validate_config(c); }),
                  "densify.grad_threshold must be a number in (0, 10^18] (got nan)");
  c = TrainConfig{};
  c.distractors.lambda_distractor = std::numeric_limits<float>::infinity();
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { validate_config(c); }),
                  "distractors.lambda_distractor must be a number in [0, 10^18] (got inf)");
}

// A config.json written before some settings existed: exactly the missing ones are named.
TEST(ConfigErrors, SettingsAbsentFromAnOlderFileAreNamed) {
  nlohmann::json j = config_to_json(TrainConfig{});
  EXPECT_TRUE(settings_absent_from(j).empty());
  j["densify"].erase("camera_path_radius");
  j["lr"].erase("means");
  EXPECT_EQ(settings_absent_from(j), (std::vector<std::string>{"lr.means", "densify.camera_path_radius"}));
  // An empty file lacks every setting config.json writes: one per leaf (an array is one setting).
  const nlohmann::json flat = config_to_json(TrainConfig{}).flatten();
  std::set<std::string> leaves;
  for (const auto& [path, value] : flat.items()) {
    const size_t last = path.rfind('/');
    const std::string tail = path.substr(last + 1);
    const bool array_element = !tail.empty() && std::all_of(tail.begin(), tail.end(), ::isdigit);
    leaves.insert(array_element ? path.substr(0, last) : path);
  }
  EXPECT_EQ(settings_absent_from(nlohmann::json::object()).size(), leaves.size());
}

}  // namespace
}  // namespace desplat
