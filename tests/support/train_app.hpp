// desplat_train and desplat_render as a user runs them (test_train_app*.cpp): a command run with
// its exit status and output, the TrainApp fixture with a small synthetic scene folder, and the
// check that a single render equals the static column of a training figure row.
#pragma once

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

namespace desplat::test {
namespace fs = std::filesystem;

struct Outcome {
  int exit_code;
  std::string output;
};

inline Outcome run(const std::string& command) {
  // One log per process: ctest runs these tests as parallel processes.
  const fs::path log = fs::temp_directory_path() / ("desplat_app_test_" + std::to_string(::getpid()) + ".log");
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  std::string text;
  {
    std::ifstream f(log);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  fs::remove(log);  // nothing left behind in the temporary folder
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
}

// `single` equals the static column (the second of five) of a training figure row.
inline void expect_static_column(const FloatImage& row, const FloatImage& single) {
  ASSERT_EQ(row.width, 5 * single.width);
  ASSERT_EQ(row.height, single.height);
  for (int y = 0; y < single.height; ++y)
    for (int x = 0; x < single.width; ++x)
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(single.pixels[3 * (size_t(y) * single.width + x) + c],
                  row.pixels[3 * (size_t(y) * row.width + single.width + x) + c])
            << "pixel " << x << "," << y;
}

class TrainApp : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("desplat_app_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    const TrainingData data = synthetic_training_data(16, 64, 48, 21);
    write_scene_folder(root_ / "scene", data);
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }
  static std::string train() { return std::string(DESPLAT_TRAIN_BIN) + " --data " + (root_ / "scene").string(); }
  static inline fs::path root_;
};

}  // namespace desplat::test
