// Structure from motion's choices and escalation (desplat/sfm/sfm.hpp) with a fake `colmap`
// (tests/support/fake_colmap.hpp): the matcher for a large capture, the escalation steps in
// order, cameras and models, the photos left out with their reasons, and the output folder.
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

// A colmap database with the tables and columns read_match_evidence uses, as colmap 3.8
// writes them: images, keypoints (rows = features), two_view_geometries (rows = inliers,
// pair_id = id1 · 2147483647 + id2).
void write_colmap_database(const fs::path& path, const std::vector<std::pair<std::string, int>>& features,
                           const std::vector<std::tuple<int, int, int>>& verified_pairs) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  std::string sql =
      "CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT UNIQUE, camera_id INTEGER);"
      "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);"
      "CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB, "
      "config INTEGER);"
      "CREATE TABLE matches (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);";
  for (size_t i = 0; i < features.size(); ++i)
    sql += "INSERT INTO images VALUES (" + std::to_string(i + 1) + ", '" + features[i].first + "', 1);" +
           "INSERT INTO keypoints VALUES (" + std::to_string(i + 1) + ", " + std::to_string(features[i].second) +
           ", 6, NULL);";
  for (const auto& [a, b, inliers] : verified_pairs)
    sql += "INSERT INTO two_view_geometries VALUES (" + std::to_string(int64_t(a) * 2147483647 + b) + ", " +
           std::to_string(inliers) + ", 2, NULL, 2);" + "INSERT INTO matches VALUES (" +
           std::to_string(int64_t(a) * 2147483647 + b) + ", " + std::to_string(inliers) + ", 2, NULL);";
  char* error = nullptr;
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error), SQLITE_OK) << (error ? error : "");
  sqlite3_close(db);
}

int count_rows(const fs::path& database, const char* table) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open(database.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  const std::string sql = std::string("SELECT COUNT(*) FROM ") + table;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  const int n = sqlite3_step(stmt) == SQLITE_ROW ? sqlite3_column_int(stmt, 0) : -1;
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return n;
}

// The lines of the fake's argument log that start with `stage`.
std::vector<std::string> calls_of(const fs::path& args_log, const std::string& stage) {
  std::vector<std::string> lines;
  std::istringstream in(slurp(args_log));
  for (std::string line; std::getline(in, line);)
    if (line.rfind(stage + " ", 0) == 0) lines.push_back(line);
  return lines;
}

// Above kExhaustiveMaxImages photos, --matcher auto reads them to judge their order: frames of
// a pan along a wall of random tiles, named in order, are matched sequentially; the same
// photos under shuffled names, exhaustively. The reason reaches the log and the result.
TEST_F(FakeColmap, AutoMatcherFollowsTheOrderOfALargeCapture) {
  const int n = sfm::kExhaustiveMaxImages + 1;
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> tone(0.0f, 1.0f);
  std::vector<float> tiles(size_t((64 + 2 * n) / 8 + 1) * 4 * 3);
  for (float& t : tiles) t = tone(rng);
  std::vector<int> slot(n);  // photo k is saved under the name of slot[k]
  std::iota(slot.begin(), slot.end(), 0);
  for (const bool shuffled : {false, true}) {
    SCOPED_TRACE(shuffled ? "shuffled names" : "names in order");
    if (shuffled) std::shuffle(slot.begin(), slot.end(), rng);
    const fs::path dir = tmp_.path() / (shuffled ? "shuffled" : "ordered");
    fs::create_directories(dir);
    colmap::Model model = fake_model(0);
    for (int k = 0; k < n; ++k) {
      desplat::FloatImage im{64, 32, 3, std::vector<float>(64 * 32 * 3)};
      for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 64; ++x)
          for (int c = 0; c < 3; ++c)
            im.pixels[(size_t(y) * 64 + x) * 3 + c] = tiles[(((x + 2 * k) / 8) * 4 + y / 8) * 3 + c];
      char name[32];
      std::snprintf(name, sizeof name, "f%03d.png", slot[k]);
      desplat::write_image(dir / name, im);
      colmap::Image image;
      image.id = static_cast<uint32_t>(k + 1);
      image.camera_id = 1;
      image.name = name;
      model.images[image.id] = image;
    }
    colmap::write_model_binary(model, tmp_.path() / (shuffled ? "m_shuffled" : "m_ordered") / "0");
    models_env_.emplace("FAKE_COLMAP_MODELS", (tmp_.path() / (shuffled ? "m_shuffled" : "m_ordered")).string());
    options_.images = dir;
    options_.out = tmp_.path() / (shuffled ? "out_shuffled" : "out_ordered");
    fs::remove(args_log_);
    const sfm::SfmResult r = sfm::run_sfm(options_);
    EXPECT_EQ(r.num_registered, n);
    const sfm::Matcher expected = shuffled ? sfm::Matcher::Exhaustive : sfm::Matcher::Sequential;
    EXPECT_EQ(r.matcher, expected);
    EXPECT_EQ(calls_of(args_log_, std::string(sfm::matcher_name(expected)) + "_matcher").size(), 1u);
    EXPECT_CONTAINS(r.matcher_reason, shuffled ? "not in file-name order" : "taken in order");
    EXPECT_CONTAINS(slurp(r.log), r.matcher_reason);
  }
  // Below the limit the photos are not read: every pair is matched whatever their order.
  options_.images = photos_;
  options_.out = tmp_.path() / "out_small";
  give_models({6});
  const sfm::SfmResult small = sfm::run_sfm(options_);
  EXPECT_EQ(small.matcher, sfm::Matcher::Exhaustive);
  EXPECT_EQ(small.matcher_reason, "exhaustive: 6 photos are few enough to match every pair");
}

TEST_F(FakeColmap, EscalatesStepByStepUntilNinetyPercentArePlacedAndKeepsTheLargestModel) {
  write_tiny_photos(photos_, 10);
  options_.escalate = true;
  const fs::path models = tmp_.path() / "models";
  colmap::write_model_binary(fake_model(6), models / "0");                   // colmap's defaults: 6 of 10
  colmap::write_model_binary(fake_model(8), models.string() + ".2" + "/0");  // relaxed mapper: 8
  colmap::write_model_binary(fake_model(10), tmp_.path() / "registered");    // registering the rest: 10
  models_env_.emplace("FAKE_COLMAP_MODELS", models.string());
  ScopedEnv registered("FAKE_COLMAP_REGISTERED", (tmp_.path() / "registered").string());
  const sfm::SfmResult r = sfm::run_sfm(options_);

  ASSERT_EQ(r.attempts.size(), 3u);  // 10 of 10 reaches 90 %: no guided matching, no more features
  EXPECT_EQ(r.attempts[0].step, "colmap defaults");
  EXPECT_EQ(r.attempts[0].registered, 6);
  EXPECT_EQ(r.attempts[1].step, "relaxed mapper");
  EXPECT_EQ(r.attempts[1].registered, 8);
  EXPECT_EQ(r.attempts[2].step, "register the rest");
  EXPECT_EQ(r.attempts[2].registered, 10);
  EXPECT_EQ(r.num_registered, 10);
  EXPECT_TRUE(r.warning.empty());
  const fs::path out = options_.out;
  const auto mappers = calls_of(args_log_, "mapper");
  ASSERT_EQ(mappers.size(), 2u);
  EXPECT_EQ(mappers[0].find("init_min_num_inliers"), std::string::npos);
  EXPECT_CONTAINS(mappers[1], "--output_path " + (out / "attempts/1-relaxed-mapper/sparse").string());
  EXPECT_CONTAINS(mappers[1],
                  "--Mapper.init_min_num_inliers 30 --Mapper.init_min_tri_angle 4 "
                  "--Mapper.abs_pose_min_num_inliers 15");
  const auto registrations = calls_of(args_log_, "image_registrator");
  ASSERT_EQ(registrations.size(), 1u);  // into the best model so far, the relaxed mapper's
  EXPECT_CONTAINS(registrations[0], "--input_path " + (out / "attempts/1-relaxed-mapper/sparse/0").string());
  EXPECT_CONTAINS(registrations[0], "--database_path " + (out / "database.db").string());
  EXPECT_EQ(calls_of(args_log_, "bundle_adjuster").size(), 1u);
  EXPECT_EQ(slurp(args_log_).find("guided_matching"), std::string::npos);
  // The winner is in sparse/0; what it replaced is kept, nothing deleted.
  EXPECT_EQ(colmap::read_model(out / "sparse/0").images.size(), 10u);
  EXPECT_EQ(colmap::read_model(out / "attempts/0-colmap-defaults/sparse/0").images.size(), 6u);
  EXPECT_EQ(colmap::read_model(out / "attempts/1-relaxed-mapper/sparse/0").images.size(), 8u);
  EXPECT_CONTAINS(slurp(r.log), "step 'relaxed mapper' (--Mapper.init_min_num_inliers 30");
  EXPECT_CONTAINS(sfm::describe_attempts(r), "register the rest: 10 of 10 photos");
}

TEST_F(FakeColmap, WhenCheapStepsFallShortItMatchesAgainOnACopyOfTheFeaturesThenExtractsMore) {
  write_tiny_photos(photos_, 10);
  options_.escalate = true;
  const fs::path models = tmp_.path() / "models";                       // no model from colmap's defaults at all
  colmap::write_model_binary(fake_model(5), models.string() + ".2/0");  // relaxed mapper
  colmap::write_model_binary(fake_model(7), models.string() + ".3/0");  // guided matching
  colmap::write_model_binary(fake_model(6), models.string() + ".4/0");  // more features
  models_env_.emplace("FAKE_COLMAP_MODELS", models.string());
  const fs::path db = tmp_.path() / "colmap.db";
  write_colmap_database(db, {{"p0.png", 900}, {"p1.png", 900}}, {{1, 2, 300}});
  ScopedEnv db_env("FAKE_COLMAP_DB", db.string());
  const sfm::SfmResult r = sfm::run_sfm(options_);

  std::vector<std::string> steps;
  for (const auto& a : r.attempts) steps.push_back(a.step + " " + std::to_string(a.registered));
  EXPECT_EQ(steps, (std::vector<std::string>{"colmap defaults 0", "relaxed mapper 5", "register the rest 5",
                                             "guided matching 7", "register the rest 7", "more features 6",
                                             "register the rest 7"}));
  EXPECT_EQ(r.num_registered, 7);
  EXPECT_EQ(r.warning,
            "3 of 10 photos could not be placed even after escalation; they are not trained on (see the "
            "list below)");
  const fs::path out = options_.out, guided = out / "attempts/3-guided-matching";
  // Guided matching ran on a copy of the first features with the matches removed (colmap's
  // matcher skips pairs it has); the first database keeps its matches.
  const auto matchers = calls_of(args_log_, "exhaustive_matcher");
  ASSERT_EQ(matchers.size(), 3u);
  EXPECT_CONTAINS(matchers[1], "--database_path " + (guided / "database.db").string());
  EXPECT_CONTAINS(matchers[1], "--SiftMatching.guided_matching 1");
  const auto extractors = calls_of(args_log_, "feature_extractor");
  ASSERT_EQ(extractors.size(), 2u);
  EXPECT_CONTAINS(extractors[1], "--database_path " + (out / "attempts/5-more-features/database.db").string());
  EXPECT_CONTAINS(extractors[1], "--SiftExtraction.max_num_features 16000 --SiftExtraction.domain_size_pooling 1");
  // The guided step's model won: its model and its database moved into place.
  EXPECT_EQ(colmap::read_model(out / "sparse/0").images.size(), 7u);
  EXPECT_EQ(count_rows(out / "database.db", "matches"), 0);
  EXPECT_EQ(count_rows(out / "database.db", "keypoints"), 2);
  EXPECT_EQ(count_rows(out / "attempts/0-colmap-defaults/database.db", "matches"), 1);
  EXPECT_FALSE(fs::exists(guided / "database.db"));
}

TEST_F(FakeColmap, AnEscalationStepThatFailsEndsTheLadderAndKeepsTheModelFound) {
  write_tiny_photos(photos_, 10);
  options_.escalate = true;
  give_models({6});
  ScopedEnv fail("FAKE_COLMAP_FAIL", "image_registrator");  // the second step breaks
  const sfm::SfmResult r = sfm::run_sfm(options_);
  ASSERT_EQ(r.attempts.size(), 3u);
  EXPECT_EQ(r.attempts[2].step, "register the rest");
  EXPECT_CONTAINS(r.attempts[2].settings, "stopped: colmap image_registrator failed with exit code 3");
  EXPECT_EQ(calls_of(args_log_, "exhaustive_matcher").size(), 1u);  // no step after the failed one
  EXPECT_EQ(r.num_registered, 6);
  EXPECT_EQ(colmap::read_model(options_.out / "sparse/0").images.size(), 6u);
}

TEST_F(FakeColmap, CamerasAndModelFollowThePhotosUnlessTheUserChooses) {
  give_models({6});
  sfm::SfmResult r = sfm::run_sfm(options_);  // six 16×16 photos without EXIF: one shared camera
  EXPECT_TRUE(r.cameras.single);
  EXPECT_CONTAINS(slurp(args_log_), "--ImageReader.camera_model OPENCV --ImageReader.single_camera 1");
  EXPECT_CONTAINS(r.attempts[0].settings, "one shared camera, OPENCV");

  desplat::write_image(photos_ / photo_name(5), desplat::FloatImage{24, 16, 3, std::vector<float>(24 * 16 * 3, 0.5f)});
  options_.overwrite = true;
  fs::remove(args_log_);
  r = sfm::run_sfm(options_);  // two sizes: one camera per photo, with colmap's own model
  EXPECT_FALSE(r.cameras.single);
  EXPECT_CONTAINS(slurp(args_log_), "--ImageReader.camera_model SIMPLE_RADIAL --ImageReader.single_camera 0");

  options_.cameras = sfm::CameraSharing::Single;
  options_.camera_model = "OPENCV_FISHEYE";
  fs::remove(args_log_);
  r = sfm::run_sfm(options_);
  EXPECT_CONTAINS(slurp(args_log_), "--ImageReader.camera_model OPENCV_FISHEYE --ImageReader.single_camera 1");
}

TEST_F(FakeColmap, WithoutEscalationOnlyColmapsDefaultsRun) {
  give_models({6});
  write_tiny_photos(photos_, 10);
  const sfm::SfmResult r = sfm::run_sfm(options_);  // escalate = false (the fixture's)
  ASSERT_EQ(r.attempts.size(), 1u);
  EXPECT_EQ(calls_of(args_log_, "mapper").size(), 1u);
  EXPECT_EQ(r.warning, "4 of 10 photos could not be placed; they are not trained on (see the list below)");
}

TEST_F(FakeColmap, ResultNamesSkippedFilesAndEveryUnplacedPhotoWithItsReason) {
  write_tiny_photos(photos_, 7);  // p0 … p6
  spit(photos_ / "empty.jpg", "");
  // Models: p0-p2 (the largest) and p5 alone. Database: p3 has 40 features; p4 has 2,000 and no
  // verified pair; p6 has 2,000 and a verified pair with p0 (50 inliers) and with p1 (20).
  const fs::path models = tmp_.path() / "models";
  colmap::write_model_binary(fake_model(3), models / "0");
  colmap::Model separate = fake_model(1);
  separate.images.begin()->second.name = "p5.png";
  colmap::write_model_binary(separate, models / "1");
  models_env_.emplace("FAKE_COLMAP_MODELS", models.string());
  const fs::path db = tmp_.path() / "colmap.db";
  write_colmap_database(db,
                        {{"p0.png", 900},
                         {"p1.png", 900},
                         {"p2.png", 900},
                         {"p3.png", 40},
                         {"p4.png", 2000},
                         {"p5.png", 900},
                         {"p6.png", 2000}},
                        {{1, 2, 300}, {1, 7, 50}, {2, 7, 20}, {1, 3, 200}});
  ScopedEnv db_env("FAKE_COLMAP_DB", db.string());
  options_.min_registered_share = 0.4;  // ⌈2.8⌉ = 3 of 7
  const sfm::SfmResult r = sfm::run_sfm(options_);
  EXPECT_EQ(r.num_photos, 7);
  ASSERT_EQ(r.skipped.size(), 1u);
  EXPECT_EQ(slurp(options_.out / "image_list.txt").find("empty.jpg"), std::string::npos);
  ASSERT_EQ(r.unregistered.size(), 4u);
  EXPECT_EQ(sfm::describe_lost_photos(r),
            "1 file(s) in the images folder were not used:\n"
            "  empty.jpg: empty file (0 bytes)\n"
            "4 of 7 photos could not be placed by structure from motion (not in the model, so not trained on):\n"
            "  p3.png: too few features (40 features): blurred, textureless or very small?\n"
            "  p4.png: 2000 features, but no verified match with any other photo (no overlap?)\n"
            "  p5.png: placed in a separate model (1, 1 photos) that colmap could not join to the largest: too few "
            "matches between the two groups\n"
            "  p6.png: 2000 features, verified matches with 2 photo(s) (at most 50), but too few to the placed "
            "photos for the mapper to place it\n");

  sfm::SfmResult many;  // long lists are cut
  many.num_photos = 30;
  for (int i = 0; i < 25; ++i) many.unregistered.push_back({photo_name(i), "why"});
  EXPECT_CONTAINS(sfm::describe_lost_photos(many, 3), "25 of 30 photos could not be placed");
  EXPECT_CONTAINS(sfm::describe_lost_photos(many, 3), "  p2.png: why\n  ... and 22 more\n");
  EXPECT_EQ(sfm::describe_lost_photos(sfm::SfmResult{}), "");
}

TEST_F(FakeColmap, WithoutADatabaseTheUnplacedPhotosAreStillNamed) {
  give_models({5});  // p0..p4 of p0..p5; the fake writes no database
  const sfm::SfmResult r = sfm::run_sfm(options_);
  ASSERT_EQ(r.unregistered.size(), 1u);
  EXPECT_EQ(r.unregistered[0].path, fs::path("p5.png"));
  EXPECT_CONTAINS(r.unregistered[0].reason, "database could not be read");
}

TEST_F(FakeColmap, EarlierResultsNeedOverwrite) {
  give_models({5});
  sfm::run_sfm(options_);
  const auto e = expect_error(options_, SfmErrorKind::OutputExists);
  EXPECT_CONTAINS(e.what(), "pass --overwrite");
  options_.overwrite = true;
  EXPECT_EQ(sfm::run_sfm(options_).num_registered, 5);
}

TEST_F(FakeColmap, InputThatIsAlreadyOutImagesIsUsedInPlace) {
  give_models({5});
  const fs::path scene = tmp_.path() / "scene";
  fs::create_directories(scene);
  fs::rename(photos_, scene / "images");
  options_.images = scene / "images";
  options_.out = scene;
  sfm::run_sfm(options_);
  EXPECT_FALSE(fs::is_symlink(scene / "images"));
  EXPECT_EQ(sfm::scan_photos(scene / "images").photos.size(), 6u);
}

TEST_F(FakeColmap, CopyImagesCopiesThePhotos) {
  give_models({5});
  options_.copy_images = true;
  sfm::run_sfm(options_);
  EXPECT_FALSE(fs::is_symlink(options_.out / "images"));
  EXPECT_EQ(sfm::scan_photos(options_.out / "images").photos.size(), 6u);
}

TEST_F(FakeColmap, OutInsideTheImagesFolderIsRefused) {
  options_.out = photos_ / "sfm";
  EXPECT_CONTAINS(expect_error(options_, SfmErrorKind::OutputExists).what(), "is inside the images folder");
}

TEST_F(FakeColmap, BadOptions) {
  options_.camera_model = "opencv";
  EXPECT_CONTAINS(expect_error(options_, SfmErrorKind::BadOptions).what(),
                  "unknown camera model 'opencv'; use one of SIMPLE_PINHOLE");
  options_.camera_model = "OPENCV";
  for (double share : {0.0, -0.5, 1.5, std::nan("")}) {
    options_.min_registered_share = share;
    EXPECT_CONTAINS(expect_error(options_, SfmErrorKind::BadOptions).what(),
                    "--min-registered-share must be in (0, 1]");
  }
}

TEST_F(FakeColmap, SequentialAndSpatialMatchersAreRun) {
  for (auto m : {sfm::Matcher::Sequential, sfm::Matcher::Spatial}) {
    ScopedEnv fail("FAKE_COLMAP_FAIL", "mapper");  // stop early: only the matcher matters
    options_.matcher = m;
    options_.overwrite = true;
    expect_error(options_, SfmErrorKind::StageFailed);
    EXPECT_CONTAINS(slurp(args_log_), std::string(sfm::matcher_name(m)) + "_matcher --database_path");
  }
}

}  // namespace
}  // namespace desplat::testing::sfm_fixture
