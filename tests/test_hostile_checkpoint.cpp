// A checkpoint that does not fit the run it is resumed into is refused with one error naming
// the file and the field, never trusted: view lists of another split, indices out of range,
// impossible steps, missing fields, non-finite parameters, another scene. Each case builds a
// real checkpoint of a small run and changes exactly what the case is about.
#include <gtest/gtest.h>

#include <unistd.h>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>

#include "desplat/io/checkpoint.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "support/expect.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

using desplat::testing::error_of;

TrainConfig tiny_config(bool distractors) {
  TrainConfig c = short_schedule(40);
  c.random_background = false;
  c.distractors.enabled = distractors;
  c.distractors.initial_count = 20;
  c.distractors.reference_pixels = 0;
  return c;
}

// A checkpoint of `data` after a few steps, as a file and as read back (source set).
struct Saved {
  std::filesystem::path file;
  Checkpoint ckpt;
};

Saved saved_after_steps(const TrainingData& data, const TrainConfig& cfg, int steps, const std::string& tag) {
  Trainer t(data, cfg);
  for (int i = 0; i < steps; ++i) t.step();
  const auto file =
      std::filesystem::temp_directory_path() / ("desplat_hostile_" + tag + "_" + std::to_string(::getpid()) + ".ckpt");
  write_checkpoint(file, make_training_checkpoint(t));
  return {file, read_checkpoint(file)};
}

// Restores `c` (written again to its file, so the CRCs are valid) into a fresh trainer.
std::string resume_error(const TrainingData& data, const TrainConfig& cfg, const Saved& s, const Checkpoint& c) {
  write_checkpoint(s.file, c);
  const Checkpoint back = read_checkpoint(s.file);
  Trainer t(data, cfg);
  return error_of<CheckpointError>([&] { restore_training_checkpoint(t, back); });
}

class HostileCheckpoint : public ::testing::Test {
 protected:
  void SetUp() override { saved_ = saved_after_steps(data_, cfg_, 7, "base"); }
  void TearDown() override { std::filesystem::remove(saved_.file); }
  std::string error_with(const std::function<void(Checkpoint&)>& change) {
    Checkpoint c = saved_.ckpt;
    change(c);
    return resume_error(data_, cfg_, saved_, c);
  }
  TrainingData data_ = synthetic_training_data(6, 64, 48, 11);
  TrainConfig cfg_ = tiny_config(false);
  Saved saved_;
};

TEST_F(HostileCheckpoint, AnIntactCheckpointStillResumes) {
  Trainer t(data_, cfg_);
  restore_training_checkpoint(t, saved_.ckpt);
  EXPECT_EQ(t.current_step(), 7);
  t.step();  // and trains on
  EXPECT_EQ(t.current_step(), 8);
}

TEST_F(HostileCheckpoint, ViewOrderIndexOutOfRangeOrNegativeIsRefused) {
  for (const int32_t bad : {4, 1000, -1, std::numeric_limits<int32_t>::min()}) {
    const std::string e = error_with([&](Checkpoint& c) {
      std::vector<int32_t> order = c.get<int32_t>("trainer/view_order");
      ASSERT_EQ(order.size(), 4u);  // views 0 and 4 are test views
      order[2] = bad;
      c.put("trainer/view_order", {order.size()}, order);
    });
    EXPECT_CONTAINS(e, saved_.file.string());
    EXPECT_CONTAINS(e, "trainer/view_order");
    EXPECT_CONTAINS(e, std::to_string(bad));
  }
}

TEST_F(HostileCheckpoint, ViewOrderOfAnotherViewCountIsRefused) {
  const std::string e = error_with([](Checkpoint& c) {
    c.put("trainer/view_order", {3}, std::vector<int32_t>{0, 1, 2});
  });
  EXPECT_CONTAINS(e, "trainer/view_order");
  EXPECT_CONTAINS(e, "lists 3 views but this run has 4");
}

TEST_F(HostileCheckpoint, NegativeOrPastTheEndViewPositionIsRefused) {
  for (const int64_t pos : {int64_t(-1), int64_t(5), int64_t(1) << 40}) {
    const std::string e = error_with([&](Checkpoint& c) { c.metadata["view_order_pos"] = pos; });
    EXPECT_CONTAINS(e, "view_order_pos");
    EXPECT_CONTAINS(e, std::to_string(pos));
  }
}

TEST_F(HostileCheckpoint, ImpossibleStepsAreRefused) {
  for (const int64_t step : {int64_t(-5), int64_t(1'000'000'000'000'000'000)}) {
    const std::string e = error_with([&](Checkpoint& c) { c.metadata["step"] = step; });
    EXPECT_CONTAINS(e, "metadata field 'step'");
    EXPECT_CONTAINS(e, std::to_string(step));
  }
  EXPECT_CONTAINS(error_with([](Checkpoint& c) { c.metadata["step"] = 5.5; }), "'step' is 5.5, not an integer");
  EXPECT_CONTAINS(error_with([](Checkpoint& c) { c.metadata["step"] = uint64_t(1) << 63; }), "not an integer");
  // An Adam step past the training step: negative would make the bias correction blow up.
  EXPECT_CONTAINS(error_with([](Checkpoint& c) { c.metadata["adam_step"] = -3; }), "'adam_step' is -3");
}

TEST_F(HostileCheckpoint, MissingStepIsOneClearSentence) {
  const std::string e = error_with([](Checkpoint& c) { c.metadata.erase("step"); });
  EXPECT_CONTAINS(e, saved_.file.string() + ": the metadata has no field 'step'");
  EXPECT_EQ(e.find("json.exception"), std::string::npos) << e;
}

TEST_F(HostileCheckpoint, NonFiniteParametersAreRefusedInOneLine) {
  const std::string e = error_with([](Checkpoint& c) {
    std::vector<float> o = c.get<float>("static/opacity_logits");
    for (float& x : o) x = std::numeric_limits<float>::quiet_NaN();
    c.put("static/opacity_logits", c.array("static/opacity_logits").shape(), o);
  });
  EXPECT_CONTAINS(e, "array 'static/opacity_logits' holds");
  EXPECT_CONTAINS(e, "not finite");
  EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  const std::string v = error_with([](Checkpoint& c) {
    std::vector<float> m = c.get<float>("static/adam_v/means");
    m[4] = -1.0f;  // a second moment is a mean of squares
    c.put("static/adam_v/means", c.array("static/adam_v/means").shape(), m);
  });
  EXPECT_CONTAINS(v, "array 'static/adam_v/means' holds 1 value that are negative or not finite");
}

TEST_F(HostileCheckpoint, CheckpointOfAnotherSplitIsRefusedNamingTheScene) {
  // The same views with another split: the checkpoint's training views are not this run's.
  TrainingData other = data_;
  other.test.push_back(other.train.back());
  other.train.pop_back();
  Trainer t(other, cfg_);
  const std::string e = error_of<CheckpointError>([&] { restore_training_checkpoint(t, saved_.ckpt); });
  EXPECT_CONTAINS(e, saved_.file.string() + ": the checkpoint belongs to another scene or split");
  EXPECT_CONTAINS(e, "it has 4 train views, this run 3");
}

TEST_F(HostileCheckpoint, CheckpointOfViewsOfAnotherSizeIsRefused) {
  const TrainingData other = synthetic_training_data(6, 80, 60, 11);
  Trainer t(other, cfg_);
  const std::string e = error_of<CheckpointError>([&] { restore_training_checkpoint(t, saved_.ckpt); });
  EXPECT_CONTAINS(e, "train view 0 is");
  EXPECT_CONTAINS(e, "at 64x48 in the checkpoint but");
  EXPECT_CONTAINS(e, "at 80x60 in this run");
}

TEST_F(HostileCheckpoint, OldCheckpointWithoutSceneRecordResumesWithAWarning) {
  Checkpoint c = saved_.ckpt;
  c.metadata.erase("scene");
  write_checkpoint(saved_.file, c);
  Trainer t(data_, cfg_);
  ::testing::internal::CaptureStdout();
  restore_training_checkpoint(t, read_checkpoint(saved_.file));
  const std::string out = ::testing::internal::GetCapturedStdout();
  EXPECT_CONTAINS(out, "records no scene");
  EXPECT_EQ(t.current_step(), 7);
}

TEST_F(HostileCheckpoint, OldCheckpointOfAnotherSplitStillCannotCrash) {
  // Without the scene record only the range checks stand between the run and a bad index.
  Checkpoint c = saved_.ckpt;
  c.metadata.erase("scene");
  write_checkpoint(saved_.file, c);
  TrainingData other = data_;
  other.train.resize(2);
  Trainer t(other, cfg_);
  ::testing::internal::CaptureStdout();
  const std::string e =
      error_of<CheckpointError>([&] { restore_training_checkpoint(t, read_checkpoint(saved_.file)); });
  ::testing::internal::GetCapturedStdout();
  EXPECT_CONTAINS(e, "trainer/view_order");
}

TEST(HostileCheckpointDeSplat, DistractorCheckpointOfAnotherSceneNamesTheScene) {
  const TrainingData fox_like = synthetic_training_data(5, 64, 48, 3);
  const Saved s = saved_after_steps(fox_like, tiny_config(true), 3, "desplat");
  const TrainingData other = synthetic_training_data(6, 64, 48, 4);
  Trainer t(other, tiny_config(false));
  const std::string e = error_of<CheckpointError>([&] { restore_training_checkpoint(t, s.ckpt); });
  std::filesystem::remove(s.file);
  EXPECT_CONTAINS(e, "belongs to another scene or split");
  EXPECT_EQ(e.find("--static-only?"), std::string::npos) << e;
}

TEST(HostileCheckpointDeSplat, DistractorListsOfTheWrongLengthAreRefused) {
  const TrainingData data = synthetic_training_data(4, 64, 48, 3);
  const TrainConfig cfg = tiny_config(true);
  const Saved s = saved_after_steps(data, cfg, 3, "lists");
  Checkpoint c = s.ckpt;
  c.metadata["distractors"]["adam_step"] = {1, 2};
  const std::string e = resume_error(data, cfg, s, c);
  c = s.ckpt;
  c.metadata["distractors"]["statistics_empty"][1] = 7;
  const std::string f = resume_error(data, cfg, s, c);
  std::filesystem::remove(s.file);
  EXPECT_CONTAINS(e, "'distractors.adam_step' is not a list of 3 entries");
  EXPECT_CONTAINS(f, "'distractors.statistics_empty[1]' is 7, not true or false");
}

}  // namespace
}  // namespace desplat::test
