// The SfM layer's pure helpers: matcher choice, defaults and the progress lines people see.
// Expectations are the documented rules (include/desplat/sfm/sfm.hpp), worked out by hand.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "desplat/sfm/sfm.hpp"

namespace sfm = desplat::sfm;

namespace {

TEST(SfmHelpers, MatcherChoiceAndDefaults) {
  EXPECT_EQ(sfm::choose_matcher(sfm::Matcher::Spatial, 5, true), sfm::Matcher::Spatial);  // the rest: test_sfm_order
  EXPECT_EQ(sfm::matcher_from_name("sequential"), sfm::Matcher::Sequential);
  EXPECT_EQ(sfm::matcher_from_name("Sequential"), std::nullopt);
  EXPECT_EQ(sfm::required_registered(0.5, 1), 3);  // never fewer than 3
  EXPECT_EQ(sfm::required_registered(0.5, 6), 3);
  EXPECT_EQ(sfm::required_registered(0.5, 7), 4);  // ⌈3.5⌉
  EXPECT_EQ(sfm::required_registered(0.5, 50), 25);
  EXPECT_EQ(sfm::required_registered(0.9, 10), 9);  // 0.9·10 in floating point is 9, not 9.000…1
  EXPECT_EQ(sfm::required_registered(1.0, 44), 44);
}

TEST(SfmHelpers, PhotosThatAgreeOnSizeAndExifShareOneCamera) {
  using sfm::CameraSharing;
  const sfm::PhotoCamera phone{1080, 1440, "Apple", "iPhone 12", 4.2f};
  const sfm::PhotoCamera plain{540, 960, "", "", 0.0f};  // video frames: no EXIF
  auto choice = sfm::choose_cameras(CameraSharing::Auto, {phone, phone, phone});
  EXPECT_TRUE(choice.single);
  EXPECT_EQ(choice.reason,
            "one shared camera: all 3 photos are 1080x1440 with the same camera make, model and "
            "focal length in EXIF (or none recorded)");
  EXPECT_TRUE(sfm::choose_cameras(CameraSharing::Auto, {plain, plain}).single);

  sfm::PhotoCamera zoomed = phone;
  zoomed.focal_mm = 6.0f;
  choice = sfm::choose_cameras(CameraSharing::Auto, {phone, zoomed, phone});
  EXPECT_FALSE(choice.single);
  EXPECT_EQ(choice.reason, "one camera per photo: the 3 photos come in one size but 2 EXIF camera/zoom settings");
  sfm::PhotoCamera smaller = plain;
  smaller.width = 270, smaller.height = 480;
  choice = sfm::choose_cameras(CameraSharing::Auto, {plain, smaller, plain});
  EXPECT_FALSE(choice.single);
  EXPECT_EQ(choice.reason, "one camera per photo: the 3 photos come in 2 image sizes");
  // What the user asks for wins.
  EXPECT_TRUE(sfm::choose_cameras(CameraSharing::Single, {plain, smaller}).single);
  EXPECT_FALSE(sfm::choose_cameras(CameraSharing::PerPhoto, {plain, plain}).single);
  EXPECT_EQ(sfm::camera_sharing_from_name("per-photo"), CameraSharing::PerPhoto);
  EXPECT_EQ(sfm::camera_sharing_from_name("single-camera"), std::nullopt);
}

TEST(SfmHelpers, TerminalProgressPrintsPlainLinesWhenNotATty) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  const auto show = sfm::terminal_progress(f, false, 1000.0);
  sfm::SfmProgress p;
  p.total = 50;
  p.unit = "image";
  show(p);  // first of a stage: printed
  p.done = 12;
  show(p);  // within the interval: dropped
  p.done = 50, p.finished = true;
  show(p);  // a stage's last report: printed
  sfm::SfmProgress m{sfm::SfmStage::Map, 31, 50, 2, "image", false};
  show(m);
  std::rewind(f);
  char buf[512] = {};
  const size_t n = std::fread(buf, 1, sizeof buf - 1, f);
  std::fclose(f);
  EXPECT_EQ(std::string(buf, n),
            "extracting features: image 0/50\nextracting features: image 50/50, done\n"
            "mapping: model 2, registered 31/50 photos\n");
}

TEST(SfmHelpers, StageTimeLimitsFollowTheDocumentedRule) {
  using sfm::SfmStage, sfm::Matcher;
  EXPECT_EQ(sfm::default_stage_time_limit(SfmStage::Extract, Matcher::Exhaustive, 50), 300 + 30 * 50);
  EXPECT_EQ(sfm::default_stage_time_limit(SfmStage::Match, Matcher::Exhaustive, 50), 600 + 3 * 1225);
  EXPECT_EQ(sfm::default_stage_time_limit(SfmStage::Match, Matcher::Sequential, 50), 600 + 60 * 50);
  EXPECT_EQ(sfm::default_stage_time_limit(SfmStage::Map, Matcher::Sequential, 50), 600 + 60 * 50);
}

}  // namespace
