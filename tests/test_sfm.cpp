// Structure from motion's failure paths (desplat/sfm/sfm.hpp), each driven by a fake `colmap`
// shell script placed first on PATH (tests/support/fake_colmap.hpp): every stage's error, time
// limits, no model, too few photos placed, bad folders, and the photo scan.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <numeric>
#include <random>
#include <sstream>

#include <OpenImageIO/imageio.h>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/sfm/sfm.hpp"
#include "sfm/match_evidence.hpp"
#include "support/expect.hpp"
#include "support/fake_colmap.hpp"
#include "support/fox_scene.hpp"
#include "support/scoped_env.hpp"
#include "support/temp_dir.hpp"

namespace desplat::testing::sfm_fixture {
namespace {

// ---- Failures with a fake colmap ---------------------------------------------------------

TEST_F(FakeColmap, RunsTheThreeStagesWithCpuOptionsAndReportsProgress) {
  give_models({5});
  options_.camera_model = "PINHOLE";
  options_.cameras = sfm::CameraSharing::Single;
  const sfm::SfmResult r = sfm::run_sfm(options_);
  EXPECT_EQ(r.num_registered, 5);
  EXPECT_EQ(r.num_photos, 6);
  EXPECT_EQ(r.matcher, sfm::Matcher::Exhaustive);

  const std::string args = slurp(args_log_);
  EXPECT_CONTAINS(args, "feature_extractor --database_path " + (options_.out / "database.db").string());
  EXPECT_CONTAINS(args, "--SiftExtraction.use_gpu 0");
  EXPECT_CONTAINS(args, "--ImageReader.camera_model PINHOLE");
  EXPECT_CONTAINS(args, "--ImageReader.single_camera 1");
  EXPECT_CONTAINS(args, "exhaustive_matcher --database_path");
  EXPECT_CONTAINS(args, "--SiftMatching.use_gpu 0");
  EXPECT_CONTAINS(args, "mapper --database_path");
  EXPECT_CONTAINS(args, "--output_path " + (options_.out / "sparse").string());

  // Layout: a link to the input, the list of photos, the log of everything the fake printed.
  EXPECT_TRUE(fs::is_symlink(options_.out / "images"));
  EXPECT_TRUE(fs::equivalent(options_.out / "images", photos_));
  EXPECT_EQ(slurp(options_.out / "image_list.txt"), "p0.png\np1.png\np2.png\np3.png\np4.png\np5.png\n");
  EXPECT_CONTAINS(slurp(r.log), "Registering image #3 (3)");

  // Progress: each stage in order, its colmap numbers parsed, and a final report per stage.
  std::vector<std::string> lines;
  for (const auto& p : progress_) lines.push_back(sfm::describe(p));
  const std::vector<std::string> expected = {"extracting features: image 0/6",
                                             "extracting features: image 1/3",
                                             "extracting features: image 3/3",
                                             "extracting features: image 3/3, done",
                                             "matching: block 0/1",
                                             "matching: block 1/1",
                                             "matching: block 1/1, done",
                                             "mapping: registered 0/6 photos",
                                             "mapping: registered 2/6 photos",
                                             "mapping: registered 3/6 photos",
                                             "mapping: registered 5/6 photos, done"};
  EXPECT_EQ(lines, expected);
}

TEST_F(FakeColmap, KeepsTheModelWithTheMostPhotosAsSparse0) {
  give_models({2, 4});
  const sfm::SfmResult r = sfm::run_sfm(options_);
  EXPECT_EQ(r.num_registered, 4);
  EXPECT_EQ(r.num_models, 2);
  EXPECT_EQ(colmap::read_model(options_.out / "sparse" / "0").images.size(), 4u);
  EXPECT_EQ(colmap::read_model(options_.out / "sparse" / "1").images.size(), 2u);
}

TEST_F(FakeColmap, ReportsAnUnreadableModel) {
  const fs::path models = tmp_.path() / "models";
  fs::create_directories(models / "0");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) spit(models / "0" / f, "garbage");
  ScopedEnv env("FAKE_COLMAP_MODELS", models.string());
  const auto e = expect_error(options_, SfmErrorKind::NoModel);
  EXPECT_CONTAINS(e.what(), "colmap mapper wrote a model that cannot be read: " + (options_.out / "sparse").string());
}

TEST_F(FakeColmap, ReportsWhichStageFailedWithItsExitCodeAndLastLines) {
  for (const char* stage : {"feature_extractor", "exhaustive_matcher", "mapper"}) {
    ScopedEnv fail("FAKE_COLMAP_FAIL", stage);
    options_.overwrite = true;
    const auto e = expect_error(options_, SfmErrorKind::StageFailed);
    EXPECT_CONTAINS(e.what(), std::string("colmap ") + stage + " failed with exit code 3");
    EXPECT_CONTAINS(e.what(), "fake colmap: disk on fire");
    EXPECT_CONTAINS(e.what(), (options_.out / "colmap.log").string());
  }
}

TEST_F(FakeColmap, ReportsColmapKilledBySignal) {
  ScopedEnv kill("FAKE_COLMAP_KILL", "mapper");
  const auto e = expect_error(options_, SfmErrorKind::StageFailed);
  EXPECT_CONTAINS(e.what(), "colmap mapper was killed by signal 9");
}

TEST_F(FakeColmap, StageRunningPastItsTimeLimitIsStopped) {
  ScopedEnv hang("FAKE_COLMAP_HANG", "exhaustive_matcher");
  options_.stage_time_limit_s = 0.5;
  const auto e = expect_error(options_, SfmErrorKind::TimedOut);
  EXPECT_CONTAINS(e.what(), "colmap exhaustive_matcher ran past its time limit of 0.5 s for 6 photos");
  EXPECT_CONTAINS(e.what(), "Matching block [1/1, 1/1]");  // its last lines
  EXPECT_CONTAINS(e.what(), "--stage-time-limit");
  options_.stage_time_limit_s = -1;
  options_.overwrite = true;
  expect_error(options_, SfmErrorKind::BadOptions);
}

TEST_F(FakeColmap, ReportsNoModel) {
  for (const char* exit_code : {"1", "0"}) {  // colmap 3.8 exits 1; a 0 without files is no better
    ScopedEnv code("FAKE_COLMAP_NO_MODEL_EXIT", exit_code);
    options_.overwrite = true;
    const auto e = expect_error(options_, SfmErrorKind::NoModel);
    EXPECT_CONTAINS(e.what(), "colmap could not build a model");
    EXPECT_CONTAINS(e.what(), "take more overlapping photos");
    EXPECT_CONTAINS(e.what(), "failed to create sparse model");
  }
}

TEST_F(FakeColmap, TooFewRegisteredKeepsThePartialModel) {
  give_models({2});  // of 6 photos; the default minimum is max(3, ⌈0.5·6⌉) = 3
  auto e = expect_error(options_, SfmErrorKind::TooFewRegistered);
  EXPECT_CONTAINS(e.what(), "only 2 of 6 photos could be placed (at least 3 needed); take more overlapping photos");
  EXPECT_EQ(std::string(e.what()).find("--min-registered-share"), std::string::npos);  // 2 photos: never enough
  // The model holds p0 and p1: the message names the four photos it lost.
  EXPECT_CONTAINS(e.what(),
                  "4 of 6 photos could not be placed by structure from motion (not in the model, so not "
                  "trained on):\n  p2.png: ");
  EXPECT_CONTAINS(e.what(), "\n  p5.png: ");
  EXPECT_EQ(colmap::read_model(options_.out / "sparse" / "0").images.size(), 2u);
}

TEST_F(FakeColmap, AShareTheUserSetsIsEnforcedAndThePartialModelCanBeAccepted) {
  give_models({3});
  options_.min_registered_share = 0.75;  // ⌈4.5⌉ = 5 of 6
  auto e = expect_error(options_, SfmErrorKind::TooFewRegistered);
  EXPECT_CONTAINS(e.what(), "only 3 of 6 photos could be placed (at least 5 needed)");
  EXPECT_CONTAINS(e.what(), "--overwrite --min-registered-share 0.50");
  options_.overwrite = true;  // what the message suggests
  options_.min_registered_share = 0.5;
  const sfm::SfmResult r = sfm::run_sfm(options_);
  EXPECT_EQ(r.num_registered, 3);
  // Above the share but under 90 %: it succeeds with a warning that says how many were lost.
  EXPECT_EQ(r.warning, "3 of 6 photos could not be placed; they are not trained on (see the list below)");
  EXPECT_CONTAINS(sfm::describe_attempts(r), "warning: 3 of 6 photos could not be placed");
}

TEST_F(FakeColmap, ColmapNotOnPath) {
  TempDir empty;
  ScopedEnv path("PATH", empty.path().string());
  const auto e = expect_error(options_, SfmErrorKind::ColmapMissing);
  EXPECT_CONTAINS(e.what(),
                  "'colmap' was not found on PATH; install it with scripts/install_deps.sh or apt-get install colmap");
  EXPECT_FALSE(fs::exists(options_.out));  // nothing written before the checks pass
}

TEST_F(FakeColmap, BadImageFolders) {
  options_.images = tmp_.path() / "missing";
  EXPECT_CONTAINS(expect_error(options_, SfmErrorKind::BadImages).what(), "does not exist");

  options_.images = tmp_.path() / "empty";
  fs::create_directories(options_.images / ".thumbnails");
  spit(options_.images / ".DS_Store", "x");
  EXPECT_CONTAINS(expect_error(options_, SfmErrorKind::BadImages).what(), "is empty");

  options_.images = tmp_.path() / "junk";
  fs::create_directories(options_.images);
  spit(options_.images / "notes.txt", "not a photo");
  spit(options_.images / "broken.jpg", "not a jpeg either");
  const auto e = expect_error(options_, SfmErrorKind::BadImages);
  EXPECT_CONTAINS(e.what(), "no readable photos in");
  EXPECT_CONTAINS(e.what(), "2 file(s)");

  options_.images = tmp_.path() / "two";
  write_tiny_photos(options_.images, 2);
  EXPECT_CONTAINS(
      expect_error(options_, SfmErrorKind::BadImages).what(),
      "found only 2 photo(s) in '" + options_.images.string() + "'; structure from motion needs at least 3");
  EXPECT_FALSE(fs::exists(options_.out));
}

// A JPEG cut short halfway through its compressed data, as a failed copy leaves it.
void write_truncated_jpeg(const fs::path& path) {
  desplat::FloatImage img{64, 64, 3, std::vector<float>(64 * 64 * 3, 0.25f)};
  for (size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = static_cast<float>((i * 37) % 101) / 100.0f;
  desplat::write_image(path, img);
  fs::resize_file(path, fs::file_size(path) * 3 / 4);
}

TEST_F(FakeColmap, FindsPhotosRecursivelyAndNamesEveryFileItSkips) {
  write_tiny_photos(photos_ / "day2", 1);
  spit(photos_ / "notes.txt", "x");
  spit(photos_ / "broken.png", "x");
  spit(photos_ / "empty.jpg", "");
  write_truncated_jpeg(photos_ / "cut.jpg");
  const sfm::PhotoScan scan = sfm::scan_photos(photos_);
  ASSERT_EQ(scan.photos.size(), 7u);
  EXPECT_EQ(scan.photos[0], fs::path("day2/p0.png"));
  ASSERT_EQ(scan.skipped.size(), 4u);  // sorted by name
  EXPECT_EQ(scan.skipped[0].path, fs::path("broken.png"));
  EXPECT_CONTAINS(scan.skipped[0].reason, "cannot be opened as an image");
  EXPECT_EQ(scan.skipped[1].path, fs::path("cut.jpg"));
  EXPECT_CONTAINS(scan.skipped[1].reason, "the JPEG is truncated");
  EXPECT_EQ(scan.skipped[2].path, fs::path("empty.jpg"));
  EXPECT_EQ(scan.skipped[2].reason, "empty file (0 bytes)");
  EXPECT_EQ(scan.skipped[3].path, fs::path("notes.txt"));
  EXPECT_CONTAINS(scan.skipped[3].reason, "not a photo");
}

// A 32×24 JPEG that records these EXIF fields (as a camera would).
void write_jpeg_with_exif(const fs::path& path, const char* make, const char* model, float focal_mm) {
  OIIO::ImageSpec spec(32, 24, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("Make", make);
  spec.attribute("Model", model);
  spec.attribute("Exif:FocalLength", focal_mm);
  const std::vector<unsigned char> pixels(32 * 24 * 3, 128);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

TEST(PhotoScan, ReadsEachPhotosSizeAndExifCamera) {
  TempDir tmp;
  write_jpeg_with_exif(tmp.path() / "a.jpg", "Apple", "iPhone 12", 4.2f);
  write_jpeg_with_exif(tmp.path() / "b.jpg", "Apple", "iPhone 12", 6.0f);
  const sfm::PhotoScan scan = sfm::scan_photos(tmp.path());
  ASSERT_EQ(scan.cameras.size(), 2u);
  EXPECT_EQ(scan.cameras[0].width, 32);
  EXPECT_EQ(scan.cameras[0].height, 24);
  EXPECT_EQ(scan.cameras[0].make, "Apple");
  EXPECT_EQ(scan.cameras[0].model, "iPhone 12");
  EXPECT_FLOAT_EQ(scan.cameras[0].focal_mm, 4.2f);
  EXPECT_FLOAT_EQ(scan.cameras[1].focal_mm, 6.0f);  // zoomed: so not one shared camera
  EXPECT_FALSE(sfm::choose_cameras(sfm::CameraSharing::Auto, scan.cameras).single);
}

}  // namespace
}  // namespace desplat::testing::sfm_fixture
