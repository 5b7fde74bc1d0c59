// Scene loading refuses bad input with one clear error naming the file and the problem, and
// loads what it can with a warning: missing folders and files, sizes that disagree, corrupt
// images and models, bad options and splits; text models and unused views load.
#include <gtest/gtest.h>

#include "support/scene_fixtures.hpp"

using namespace scene_test;

// ---- Bad input ------------------------------------------------------------------------------

TEST(SceneErrors, MissingFolders) {
  TempDir dir("missing");
  write_synthetic(dir.path());
  Warnings w;
  TempDir cache("missing_cache");
  fs::rename(dir.path() / "images", dir.path() / "photos");
  std::string e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path()) / "images").string());
  EXPECT_CONTAINS(e, "missing images/ folder");
  fs::rename(dir.path() / "photos", dir.path() / "images");
  fs::rename(dir.path() / "sparse/0", dir.path() / "sparse/1");
  e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path()) / "sparse/0").string());
  EXPECT_CONTAINS(e, "missing sparse/0/ folder");
  EXPECT_CONTAINS(
      error_of<SceneError>([&] { load_colmap_scene(dir.path() / "nowhere", quiet_options(cache.path(), w)); }),
      "nowhere: missing scene folder");
}

TEST(SceneErrors, RegisteredImageWithoutAFile) {
  TempDir dir("nofile");
  TempDir cache("nofile_cache");
  write_synthetic(dir.path());
  fs::remove(dir.path() / "images/img_2.png");
  Warnings w;
  const std::string e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, (fs::absolute(dir.path()) / "images/img_2.png").string());
  EXPECT_CONTAINS(e, "no file for image 'img_2.png' (image id 3 in");
  EXPECT_CONTAINS(e, "images.bin");
}

TEST(SceneErrors, ImageSizeDisagreesWithItsCamera) {
  TempDir dir("size");
  TempDir cache("size_cache");
  write_synthetic(dir.path());
  write_image(dir.path() / "images/img_1.png", pattern_image(63, 48, 1));
  Warnings w;
  std::string e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, "img_1.png: image is 63x48 px but its COLMAP camera 1 is 64x48 px");
  // A downscaled photo in images/ is not explained by the downscale (that is images_N/'s job).
  write_image(dir.path() / "images/img_1.png", pattern_image(32, 24, 1));
  e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w, 2)); });
  EXPECT_CONTAINS(e, "img_1.png: image is 32x24 px but its COLMAP camera 1 is 64x48 px");
}

TEST(SceneErrors, UnreadableOrCorruptImages) {
  TempDir dir("corrupt");
  TempDir cache("corrupt_cache");
  write_synthetic(dir.path());
  Warnings w;
  const fs::path bad = dir.path() / "images/img_0.png";
  spit(bad, "this is not an image");
  std::string e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, fs::absolute(bad).string());
  EXPECT_CONTAINS(e, "cannot read image");
  // A truncated file whose header is intact passes the load and fails when its pixels are read.
  write_image(bad, pattern_image(64, 48, 0));
  const std::string bytes = slurp(bad);
  spit(bad, bytes.substr(0, bytes.size() / 2));
  const Scene scene = load_colmap_scene(dir.path(), quiet_options(cache.path(), w));
  e = error_of<SceneError>([&] { load_view_image(scene, 0); });
  EXPECT_CONTAINS(e, fs::absolute(bad).string());
}

TEST(SceneErrors, ModelProblemsReportedByTheColmapReader) {
  TempDir dir("model");
  TempDir cache("model_cache");
  write_synthetic(dir.path());
  Warnings w;
  const fs::path images_bin = dir.path() / "sparse/0/images.bin";
  const fs::path points_bin = dir.path() / "sparse/0/points3D.bin";
  const std::string images = slurp(images_bin), points = slurp(points_bin);

  // Duplicate names: rename img_1.png to img_0.png in place (same length).
  std::string dup = images;
  const size_t at = dup.find("img_1.png");
  ASSERT_NE(at, std::string::npos);
  dup[at + 4] = '0';
  spit(images_bin, dup);
  std::string e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, images_bin.string());
  EXPECT_CONTAINS(e, "duplicate image name 'img_0.png'");

  // NaN in a pose: images.bin = uint64 count, then per image uint32 id, qw qx qy qz tx ty tz.
  std::string nan_pose = images;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(nan_pose.data() + 8 + 4 + 4 * 8, &nan, 8);  // tx of the first image
  spit(images_bin, nan_pose);
  e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, images_bin.string());
  EXPECT_CONTAINS(e, "tx is nan");
  spit(images_bin, images);

  // Inf in a point: points3D.bin = uint64 count, then per point uint64 id, x y z.
  std::string inf_point = points;
  const double inf = std::numeric_limits<double>::infinity();
  std::memcpy(inf_point.data() + 8 + 8 + 8, &inf, 8);  // y of the first point
  spit(points_bin, inf_point);
  e = error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w)); });
  EXPECT_CONTAINS(e, points_bin.string());
  EXPECT_CONTAINS(e, "y is inf");
}

TEST(SceneErrors, EmptyPointCloudLoadsWithAWarning) {
  TempDir dir("nopoints");
  TempDir cache("nopoints_cache");
  write_synthetic(dir.path(), CameraModelId::Pinhole, 4, 64, 48, /*points=*/0);
  Warnings w;
  const Scene scene = load_colmap_scene(dir.path(), quiet_options(cache.path(), w));
  EXPECT_TRUE(scene.points_xyz.empty());
  EXPECT_TRUE(scene.points_rgb.empty());
  ASSERT_EQ(w.seen.size(), 1u);
  EXPECT_CONTAINS(w.seen[0], "no 3D points");
  EXPECT_EQ(scene.views.size(), 4u);
}

TEST(SceneErrors, BadOptionsAndSplits) {
  TempDir dir("options");
  TempDir cache("options_cache");
  write_synthetic(dir.path());
  Warnings w;
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(cache.path(), w, 0)); }),
                  "downscale must be at least 1");
  SceneOptions o = quiet_options(cache.path(), w);
  o.split.rule = SplitRule::RobustNeRF;  // img_*.png has none of the RobustNeRF keywords
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_colmap_scene(dir.path(), o); }),
                  "'img_0.png' must contain exactly one of");
  o.split.rule = SplitRule::OnTheGo;
  o.split.every_nth = 4;  // belongs to another rule
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_colmap_scene(dir.path(), o); }), "does not use every_nth");
  EXPECT_CONTAINS(
      error_of<SceneError>([&] { load_colmap_scene(dir.path(), quiet_options(dir.path() / "images/.cache", w)); }),
      "the image cache must be outside the input folder");
  EXPECT_CONTAINS(error_of<SceneError>([&] {
                    const Scene s = load_colmap_scene(dir.path(), quiet_options(cache.path(), w));
                    load_view_image(s, 99);
                  }),
                  "view 99 does not exist");
}

TEST(SceneLoad, TextModelsAndUnusedViews) {
  TempDir dir("text");
  TempDir cache("text_cache");
  const Synthetic s = write_synthetic(dir.path(), CameraModelId::Pinhole, 6, 64, 48);
  fs::remove_all(dir.path() / "sparse/0");
  colmap::write_model_text(s.model, dir.path() / "sparse/0");
  std::ofstream(dir.path() / "train.txt") << "img_1.png\nimg_3.png\n";
  std::ofstream(dir.path() / "test.txt") << "img_5.png\n";
  Warnings w;
  SceneOptions o = quiet_options(cache.path(), w);
  o.split.rule = SplitRule::NameLists;
  o.split.train_list = dir.path() / "train.txt";
  o.split.test_list = dir.path() / "test.txt";
  const Scene scene = load_colmap_scene(dir.path(), o);
  ASSERT_EQ(scene.views.size(), 3u);  // the other three are unused
  EXPECT_EQ(scene.views[0].name, "img_1.png");
  EXPECT_FALSE(scene.views[0].is_test);
  EXPECT_TRUE(scene.views[2].is_test);
  // Normalization still uses all six cameras.
  double largest = 0;
  for (const auto& [id, im] : s.model.images) {
    const auto c = scene.normalization.to_normalized({center(im).x(), center(im).y(), center(im).z()});
    for (double v : c) largest = std::max(largest, std::abs(v));
  }
  EXPECT_NEAR(largest, 1.0, 1e-12);
}

TEST(SceneLoad, SingleCameraKeepsTheScale) {
  TempDir dir("single");
  TempDir cache("single_cache");
  const Synthetic s = write_synthetic(dir.path(), CameraModelId::Pinhole, 1, 64, 48);
  Warnings w;
  SceneOptions o = quiet_options(cache.path(), w);
  o.split.rule = SplitRule::AllTrain;  // every-8th would hold out the only view
  const Scene scene = load_colmap_scene(dir.path(), o);
  EXPECT_EQ(scene.normalization.scale, 1.0);
  const Eigen::Vector3d c = center(s.model.images.begin()->second);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(scene.normalization.center[k], c[k], 1e-12);
  for (float v : scene.views[0].camera.center()) EXPECT_NEAR(v, 0.0f, 1e-6f);
}
