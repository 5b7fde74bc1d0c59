// The settings table as config.json and --config read it: values are checked as written
// (an integer setting refuses 1.7, a 32-bit count refuses 1e20 naming 1e20, a negative seed is
// refused), every message states the whole allowed range, old names still read, and the
// reference (docs/CONFIG.md) lists exactly the settings config.json holds.
#include <gtest/gtest.h>

#include <cctype>
#include <set>
#include <string>

#include "desplat/train/train_config_json.hpp"
#include "support/expect.hpp"

namespace desplat {
namespace {

std::string error_for(const nlohmann::json& j) {
  return testing::error_of<std::invalid_argument>([&] { config_from_json(j); });
}

TEST(Settings, IntegerSettingsRefuseFractions) {
  EXPECT_CONTAINS(error_for({{"num_downscales", 1.7}}),
                  "config: num_downscales must be an integer in [0, 10] (got 1.7)");
  EXPECT_CONTAINS(error_for({{"densify", {{"refine_every", 99.5}}}}), "densify.refine_every must be an integer");
  // A whole number written with a point is that integer.
  EXPECT_EQ(config_from_json({{"num_downscales", 1.0}}).num_downscales, 1);
}

TEST(Settings, ValuesBeyondTheTypeAreNamedAsWritten) {
  EXPECT_CONTAINS(error_for({{"num_downscales", 1e20}}), "num_downscales must be an integer in [0, 10] (got 1e+20)");
  // A 32-bit interval: 3e9 would wrap to a negative count.
  EXPECT_CONTAINS(error_for({{"resolution_schedule", 3000000000LL}}),
                  "resolution_schedule must be an integer in [1, 2147483647] (got 3000000000)");
  EXPECT_CONTAINS(error_for({{"seed", -1}}), "seed must be an integer in [0, 18446744073709551615] (got -1)");
  EXPECT_EQ(config_from_json({{"seed", 18446744073709551615ULL}}).seed, 18446744073709551615ULL);
}

TEST(Settings, MessagesStateTheWholeRange) {
  EXPECT_CONTAINS(error_for({{"lr", {{"means", 1e30}}}}),
                  "config: lr.means must be a number in (0, 10^18] (got 1e+30)");
  EXPECT_CONTAINS(error_for({{"iterations", 2e18}}), "iterations must be an integer in [1, 10^18] (got 2e+18)");
  EXPECT_CONTAINS(error_for({{"appearance", {{"test_lr", 0}}}}),
                  "appearance.test_lr must be a number in (0, 10^18] (got 0)");
}

TEST(Settings, TypesAreCheckedWithTheSettingNamed) {
  EXPECT_CONTAINS(error_for({{"densify", {{"enabled", 1}}}}), "config: densify.enabled must be true or false (got 1)");
  EXPECT_CONTAINS(error_for({{"iterations", "many"}}), "iterations must be an integer in [1, 10^18] (got \"many\")");
  EXPECT_CONTAINS(error_for({{"eval_background", {0.1, 0.2}}}),
                  "eval_background must be three numbers, each in [0, 1] (got [0.1,0.2])");
}

// One name per setting: the colour rates are lr.colors_dc / lr.colors_rest and
// distractors.lr.colors_dc; the names older files used still read.
TEST(Settings, OldNamesReadAsTodays) {
  const TrainConfig c =
      config_from_json({{"lr", {{"sh_dc", 0.125}, {"sh_rest", 0.25}}}, {"distractors", {{"lr", {{"rgb", 0.5}}}}}});
  EXPECT_EQ(c.lr.colors_dc, 0.125f);
  EXPECT_EQ(c.lr.colors_rest, 0.25f);
  EXPECT_EQ(c.distractors.lr.colors_dc, 0.5f);
  const nlohmann::json j = config_to_json(c);
  EXPECT_EQ(j["lr"]["colors_dc"], 0.125);
  EXPECT_EQ(j["distractors"]["lr"]["colors_dc"], 0.5);
  EXPECT_FALSE(j["lr"].contains("sh_dc"));
  EXPECT_FALSE(j["distractors"]["lr"].contains("rgb"));
  // A file with an old name lacks nothing.
  nlohmann::json old = j;
  old["lr"].erase("colors_dc");
  old["lr"]["sh_dc"] = 0.125;
  EXPECT_TRUE(settings_absent_from(old).empty());
  EXPECT_CONTAINS(error_for({{"lr", {{"sh_dc", 0.1}, {"colors_dc", 0.2}}}}),
                  "lr.sh_dc is the old name of lr.colors_dc and both are given: keep only lr.colors_dc");
}

// The distractors' rates by name, as the paper's §6 gives them.
TEST(Settings, DistractorRatesAreTheDocumentedOnes) {
  const nlohmann::json j = config_to_json(TrainConfig{});
  EXPECT_FLOAT_EQ(j["distractors"]["lr"]["means"].get<float>(), 1.6e-4f);
  EXPECT_FLOAT_EQ(j["distractors"]["lr"]["log_scales"].get<float>(), 5e-2f);
  EXPECT_FLOAT_EQ(j["distractors"]["lr"]["quats"].get<float>(), 1e-2f);
  EXPECT_FLOAT_EQ(j["distractors"]["lr"]["opacity_logits"].get<float>(), 5e-2f);
  EXPECT_FLOAT_EQ(j["distractors"]["lr"]["colors_dc"].get<float>(), 2.5e-2f);
}

// The reference lists exactly the settings config.json holds, each with a type, a range, the
// default config.json writes and a one-sentence meaning.
TEST(Settings, ReferenceDescribesEverySettingOnce) {
  const nlohmann::json flat = config_to_json(TrainConfig{}).flatten();
  std::set<std::string> written;
  for (const auto& [path, value] : flat.items()) {
    std::string name = path.substr(1);
    if (const size_t slash = name.rfind('/'); slash != std::string::npos && std::isdigit(name[slash + 1]))
      name = name.substr(0, slash);  // an array element: its setting
    for (char& ch : name)
      if (ch == '/') ch = '.';
    written.insert(name);
  }
  std::set<std::string> described;
  for (const SettingDescription& s : describe_settings()) {
    EXPECT_TRUE(described.insert(s.name).second) << s.name << " is described twice";
    EXPECT_FALSE(s.type.empty()) << s.name;
    EXPECT_FALSE(s.range.empty()) << s.name;
    EXPECT_FALSE(s.default_value.empty()) << s.name;
    ASSERT_FALSE(s.meaning.empty()) << s.name;
    EXPECT_TRUE(s.meaning.back() == '.' || s.meaning.ends_with("…")) << s.name << ": one sentence";
  }
  EXPECT_EQ(described, written);
  const std::string md = settings_reference_markdown();
  for (const std::string& name : written) EXPECT_CONTAINS(md, "| `" + name + "` |");
}

// Every integer setting's stated range is what validation enforces: one below the lower end
// and one above the upper end are refused naming the setting and the range; both ends are
// accepted.
TEST(Settings, StatedIntegerRangesAreEnforced) {
  const auto with = [](const std::string& name, long long v) {
    std::string p = "/" + name;
    for (char& ch : p)
      if (ch == '.') ch = '/';
    nlohmann::json j = nlohmann::json::object();
    j[nlohmann::json::json_pointer(p)] = v;
    return j;
  };
  int checked = 0;
  for (const SettingDescription& s : describe_settings()) {
    if (s.type != "integer" || s.name == "seed") continue;  // seed: the whole uint64 range
    const size_t open = s.range.find('['), comma = s.range.find(", ", open), close = s.range.find(']', comma);
    ASSERT_NE(close, std::string::npos) << s.name << ": " << s.range;
    const long long lo = std::stoll(s.range.substr(open + 1, comma - open - 1));
    const std::string hi_text = s.range.substr(comma + 2, close - comma - 2);
    const long long hi = hi_text == "10^18" ? 1000000000000000000LL : std::stoll(hi_text);
    EXPECT_CONTAINS(error_for(with(s.name, lo - 1)), "config: " + s.name + " must be " + s.range);
    EXPECT_CONTAINS(error_for(with(s.name, hi + 1)), "config: " + s.name + " must be " + s.range);
    EXPECT_NO_THROW(config_from_json(with(s.name, lo))) << s.name;
    // batch is also bounded by densify.refine_every (Batch.ABatchLargerThanTheRefinementPeriodIsRefused),
    // so its upper end is taken with a refinement period that allows it.
    nlohmann::json at_hi = with(s.name, hi);
    if (s.name == "batch") at_hi["densify"]["refine_every"] = hi;
    EXPECT_NO_THROW(config_from_json(at_hi)) << s.name;
    ++checked;
  }
  EXPECT_GT(checked, 30);
}

}  // namespace
}  // namespace desplat
