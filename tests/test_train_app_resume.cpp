// desplat_train interrupted and resumed: the checkpoint on Ctrl-C, and --resume keeping the
// settings the model was trained with.
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

TEST_F(TrainApp, InterruptWritesCheckpointAndResumeFinishes) {
  const fs::path out = root_ / "interrupted";
  // SIGINT after 3 s of a run far too long to finish.
  // (--effects names the set, so no transient probe runs before training.)
  const Outcome r = run("timeout --preserve-status -s INT 3 " + train() + " --out " + out.string() +
                        " --iterations 1000000 --threads 2 --effects distractors");
  ASSERT_EQ(r.exit_code, 130) << r.output;
  EXPECT_NE(r.output.find("interrupted at step"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(out / "checkpoint.ckpt"));
  // The default --effects auto resumes with the effects the model was trained with.
  const Outcome resumed = run(train() + " --out " + out.string() + " --iterations 150 --threads 2 --resume");
  // Either it resumed below 150 and finished, or the interrupted run had passed 150 already.
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resumed from"), std::string::npos) << resumed.output;
  EXPECT_NE(resumed.output.find("--effects auto: distractors, as this model was trained"), std::string::npos)
      << resumed.output;
  EXPECT_EQ(resumed.output.find("probing for transients"), std::string::npos) << resumed.output;
  EXPECT_TRUE(fs::exists(out / "metrics.json"));
}

// --resume continues with the settings config.json records: a run started with --preset fast
// and resumed without it goes on as fast (resolution_schedule 1000 against the default's
// 3000), a resume naming other settings is refused with each difference named and nothing
// written, and one naming the same settings goes through.
TEST_F(TrainApp, ResumeKeepsTheTrainedSettingsAndRefusesOtherOnes) {
  const fs::path out = root_ / "resume_settings";
  const std::string first = train() + " --out " + out.string() + " --threads 2 --effects distractors --preset fast";
  ASSERT_EQ(run(first + " --iterations 20").exit_code, 0);
  auto recorded = [&] {
    nlohmann::json c;
    std::ifstream(out / "config.json") >> c;
    return c;
  };
  ASSERT_EQ(recorded()["train"]["resolution_schedule"], 1000);
  const std::string checkpoint_before = desplat::testing::slurp(out / "checkpoint.ckpt");

  const Outcome refused = run(train() + " --out " + out.string() + " --resume --iterations 40 --preset paper");
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("--resume continues the model with the settings it was trained with"),
            std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find("resolution_schedule 3000 (1000 in " + (out / "config.json").string() + ")"),
            std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find(" more. Resume without settings options"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("started with --preset fast and effects distractors"), std::string::npos)
      << refused.output;
  EXPECT_EQ(refused.output.find("iterations 40"), std::string::npos) << refused.output;  // may change
  // One setting changed by a config file on top of the first run's preset: exactly that one.
  const fs::path one_change = root_ / "radius_005.json";
  write_file_atomically(one_change, R"({"densify": {"camera_path_radius": 0.05}})");
  const Outcome one = run(first + " --resume --iterations 40 --config " + one_change.string());
  EXPECT_EQ(one.exit_code, 1) << one.output;
  EXPECT_NE(one.output.find("changes 1 of them: densify.camera_path_radius 0.05 (0.08 in " +
                            (out / "config.json").string() + ")."),
            std::string::npos)
      << one.output;
  EXPECT_EQ(desplat::testing::slurp(out / "checkpoint.ckpt"), checkpoint_before);
  EXPECT_EQ(recorded()["train"]["iterations"], 20);

  const Outcome resumed = run(train() + " --out " + out.string() + " --resume --iterations 40");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resumed from"), std::string::npos) << resumed.output;
  EXPECT_NE(resumed.output.find("at step 20"), std::string::npos) << resumed.output;
  EXPECT_EQ(recorded()["train"]["resolution_schedule"], 1000);
  EXPECT_EQ(recorded()["train"]["iterations"], 40);
  EXPECT_EQ(recorded()["run"]["preset"], "fast");

  const Outcome same = run(first + " --resume --iterations 50");
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("at step 40"), std::string::npos) << same.output;
  EXPECT_EQ(same.output.find("records no value"), std::string::npos) << same.output;

  // A config.json from a build before a setting existed: the resume says which it defaults.
  nlohmann::json older = recorded();
  older["train"]["densify"].erase("camera_path_radius");
  write_file_atomically(out / "config.json", older.dump(2));
  const Outcome old_file = run(train() + " --out " + out.string() + " --resume --iterations 60");
  ASSERT_EQ(old_file.exit_code, 0) << old_file.output;
  EXPECT_NE(old_file.output.find("warning: " + (out / "config.json").string() +
                                 " records no value for 1 setting (densify.camera_path_radius)"),
            std::string::npos)
      << old_file.output;
  EXPECT_TRUE(recorded()["train"]["densify"].contains("camera_path_radius"));  // written back
}

}  // namespace
}  // namespace desplat::test
