// The capture evidence run_sfm reads from colmap's database after matching
// (src/sfm/two_view_evidence.hpp, include/desplat/sfm/sfm.hpp): relative motion from an essential
// matrix against the poses it was made from, the evidence of databases written here with known
// two-view geometries (a forward walk, an orbit), the forward-walk rule at its boundary, and the
// ladder (with the fake colmap) choosing the mapper's thresholds from it and not matching again
// when every photo left out has matches.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <random>
#include <sstream>

#include "desplat/sfm/sfm.hpp"
#include "sfm/two_view_evidence.hpp"
#include "support/expect.hpp"
#include "support/fake_colmap.hpp"
#include "support/scoped_env.hpp"
#include "support/temp_dir.hpp"

namespace desplat::testing::sfm_fixture {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kDeg = std::numbers::pi / 180;

Matrix3d cross_matrix(const Vector3d& v) {
  Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// A camera as world-to-camera rotation and centre.
struct Pose {
  Matrix3d R;  // rows: camera x, y, z in world
  Vector3d C;
  Vector3d to_camera(const Vector3d& X) const { return R * (X - C); }
};

// Camera 2 relative to camera 1 in colmap's convention (p2 = R·p1 + t).
std::pair<Matrix3d, Vector3d> relative(const Pose& a, const Pose& b) {
  const Matrix3d R = b.R * a.R.transpose();
  return {R, b.R * (a.C - b.C)};
}

// Looking from c along `forward` (horizontal), world z up, camera y down.
Pose looking(const Vector3d& c, const Vector3d& forward) {
  const Vector3d f = forward.normalized(), right = f.cross(Vector3d::UnitZ()).normalized(), down = f.cross(right);
  Pose p;
  p.R.row(0) = right.transpose();
  p.R.row(1) = down.transpose();
  p.R.row(2) = f.transpose();
  p.C = c;
  return p;
}

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Points of a street ahead of the cameras: two walls at y = ±3 and the ground, x in [4, 30].
std::vector<Vector3d> street_points(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> along(4, 30), across(-3, 3), up(0, 6);
  std::vector<Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    switch (i % 3) {
      case 0:
        pts.emplace_back(along(rng), 3, up(rng));
        break;
      case 1:
        pts.emplace_back(along(rng), -3, up(rng));
        break;
      default:
        pts.emplace_back(along(rng), across(rng), 0);
        break;
    }
  }
  return pts;
}

// ---- Relative motion from an essential matrix --------------------------------------------------

// Camera 2 a step ahead of camera 1 (and, in the second case, a step to the side), turned by a
// few degrees: the recovered baseline direction, its forward share and the median angle at which
// the rays meet equal those of the poses and points the correspondences were made from.
TEST(CaptureEvidence, MotionFromEssentialMatchesThePosesItWasMadeFrom) {
  const std::vector<Vector3d> world = street_points(300, 3);
  for (const Vector3d& step : {Vector3d(0.3, 0.02, 0.01), Vector3d(0.1, 0.5, 0)}) {
    SCOPED_TRACE("step " + std::to_string(step.x()) + ", " + std::to_string(step.y()));
    const Pose a = looking({0, 0, 1.6}, {1, 0, 0});
    const Pose b = looking(a.C + step, {std::cos(3 * kDeg), std::sin(3 * kDeg), 0});
    const auto [R, t] = relative(a, b);
    std::vector<Vector2d> x1, x2;
    std::vector<double> angles;
    for (const Vector3d& X : world) {
      const Vector3d p1 = a.to_camera(X), p2 = b.to_camera(X);
      x1.emplace_back(p1.x() / p1.z(), p1.y() / p1.z());
      x2.emplace_back(p2.x() / p2.z(), p2.y() / p2.z());
      angles.push_back(std::acos((X - a.C).normalized().dot((X - b.C).normalized())) / kDeg);
    }
    const auto m = sfm::motion_from_essential(cross_matrix(t) * R, x1, x2);
    ASSERT_TRUE(m.has_value());
    EXPECT_EQ(m->points_in_front, static_cast<int>(world.size()));
    EXPECT_LT((m->t - t.normalized()).norm(), 1e-6);
    EXPECT_LT((m->R - R).norm(), 1e-6);
    EXPECT_NEAR(m->forward, std::abs(t.normalized().z()), 1e-6);
    EXPECT_NEAR(m->median_tri_angle_deg, median_of(angles), 1e-6);
  }
  EXPECT_FALSE(sfm::motion_from_essential(Matrix3d::Zero(), {{0, 0}}, {{0, 0}}).has_value());
  EXPECT_FALSE(sfm::motion_from_essential(Matrix3d::Identity(), {{0, 0}}, {}).has_value());
}

// ---- Databases with known two-view geometries ------------------------------------------------

constexpr double kFocal = 500, kCx = 320, kCy = 240;

template <class T>
std::string blob_of(const std::vector<T>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

// A colmap 3.8 database (the tables and columns colmap writes): one PINHOLE camera (f = 500 px,
// 640×480), one photo per pose ("p0.png", …) with the points it sees as keypoints (6 columns, as
// colmap's affine keypoints; a point farther than `max_depth` ahead is too small to be found),
// and every pair that shares at least `min_shared` points as a
// verified pair: its inlier matches and F (row-major, as colmap stores it) or, with
// `calibrated`, E (config 2 instead of 3).
void write_database(const fs::path& path, const std::vector<Pose>& poses, const std::vector<Vector3d>& world,
                    bool calibrated, double max_depth = 1e9, int min_shared = 30) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const char* schema =
      "CREATE TABLE cameras (camera_id INTEGER PRIMARY KEY, model INTEGER, width INTEGER, height INTEGER, "
      "params BLOB, prior_focal_length INTEGER);"
      "CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT UNIQUE, camera_id INTEGER);"
      "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);"
      "CREATE TABLE matches (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);"
      "CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB, "
      "config INTEGER, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB);";
  ASSERT_EQ(sqlite3_exec(db, schema, nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  auto run = [&](const char* sql, const std::vector<std::pair<int, std::string>>& blobs,
                 const std::vector<std::pair<int, int64_t>>& ints) {
    ASSERT_EQ(sqlite3_prepare_v2(db, sql, -1, &stmt, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
    for (const auto& [i, b] : blobs) sqlite3_bind_blob(stmt, i, b.data(), static_cast<int>(b.size()), SQLITE_TRANSIENT);
    for (const auto& [i, v] : ints) sqlite3_bind_int64(stmt, i, v);
    ASSERT_EQ(sqlite3_step(stmt), SQLITE_DONE) << sqlite3_errmsg(db);
    sqlite3_finalize(stmt);
  };
  run("INSERT INTO cameras VALUES (1, 1, 640, 480, ?1, 0)",
      {{1, blob_of(std::vector<double>{kFocal, kFocal, kCx, kCy})}}, {});
  Matrix3d K;
  K << kFocal, 0, kCx, 0, kFocal, kCy, 0, 0, 1;
  // visible[k][i]: the keypoint index of point i in photo k, or -1.
  std::vector<std::vector<int>> visible(poses.size(), std::vector<int>(world.size(), -1));
  for (size_t k = 0; k < poses.size(); ++k) {
    std::vector<float> kp;
    for (size_t i = 0; i < world.size(); ++i) {
      const Vector3d p = poses[k].to_camera(world[i]);
      if (p.z() <= 0.1 || p.z() > max_depth) continue;
      const double x = kFocal * p.x() / p.z() + kCx, y = kFocal * p.y() / p.z() + kCy;
      if (x < 0 || y < 0 || x > 640 || y > 480) continue;
      visible[k][i] = static_cast<int>(kp.size() / 6);
      kp.insert(kp.end(), {float(x), float(y), 1, 0, 0, 1});
    }
    const std::string name = photo_name(static_cast<int>(k));
    ASSERT_EQ(sqlite3_exec(db, ("INSERT INTO images VALUES (" + std::to_string(k + 1) + ", '" + name + "', 1)").c_str(),
                           nullptr, nullptr, nullptr),
              SQLITE_OK);
    run("INSERT INTO keypoints VALUES (?2, ?3, 6, ?1)", {{1, blob_of(kp)}},
        {{2, int64_t(k + 1)}, {3, int64_t(kp.size() / 6)}});
  }
  for (size_t a = 0; a < poses.size(); ++a)
    for (size_t b = a + 1; b < poses.size(); ++b) {
      std::vector<uint32_t> m;
      for (size_t i = 0; i < world.size(); ++i)
        if (visible[a][i] >= 0 && visible[b][i] >= 0)
          m.insert(m.end(), {uint32_t(visible[a][i]), uint32_t(visible[b][i])});
      if (static_cast<int>(m.size() / 2) < min_shared) continue;
      const auto [R, t] = relative(poses[a], poses[b]);
      const Matrix3d E = cross_matrix(t) * R, F = K.inverse().transpose() * E * K.inverse();
      std::vector<double> e(9), f(9);
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) e[3 * r + c] = E(r, c), f[3 * r + c] = F(r, c);
      const int64_t pair = int64_t(a + 1) * 2147483647 + int64_t(b + 1);
      run("INSERT INTO two_view_geometries VALUES (?3, ?4, 2, ?1, ?5, ?2, ?6, NULL, NULL, NULL)",
          {{1, blob_of(m)}, {2, blob_of(f)}, {6, calibrated ? blob_of(e) : std::string()}},
          {{3, pair}, {4, int64_t(m.size() / 2)}, {5, calibrated ? 2 : 3}});
    }
  sqlite3_close(db);
}

// Eight photos walking down the street, a step of 0.4 apart, swaying by up to 5 cm.
std::vector<Pose> walk_poses() {
  std::vector<Pose> poses;
  for (int k = 0; k < 8; ++k) poses.push_back(looking({0.4 * k, 0.05 * std::sin(k), 1.6}, {1, 0, 0}));
  return poses;
}

// Eight photos on a 90° arc of radius 8 around the middle of the street, looking at it.
std::vector<Pose> orbit_poses() {
  std::vector<Pose> poses;
  const Vector3d centre(17, 0, 2);
  for (int k = 0; k < 8; ++k) {
    const double a = (-135 + 90.0 * k / 7) * kDeg;
    const Vector3d c = centre + Vector3d(8 * std::cos(a), 8 * std::sin(a), 0.5);
    poses.push_back(looking(c, centre - c));
  }
  return poses;
}

TEST(CaptureEvidence, AForwardWalkIsRecognisedFromItsDatabase) {
  TempDir tmp;
  const std::vector<Pose> poses = walk_poses();
  for (const bool calibrated : {false, true}) {
    SCOPED_TRACE(calibrated ? "E stored (calibrated)" : "F stored (uncalibrated)");
    const fs::path db = tmp.path() / (calibrated ? "e.db" : "f.db");
    write_database(db, poses, street_points(1500, 5), calibrated, 12);
    const sfm::CaptureGeometry g = sfm::read_capture_geometry(db);
    ASSERT_EQ(g.names.size(), 8u);
    ASSERT_EQ(g.pairs.size(), 28u);  // every pair sees the street ahead
    for (const sfm::PairGeometry& p : g.pairs) {
      ASSERT_TRUE(p.motion.has_value()) << p.image1 << "-" << p.image2;
      const auto [R, t] = relative(poses[size_t(p.image1 - 1)], poses[size_t(p.image2 - 1)]);
      EXPECT_NEAR(p.motion->forward, std::abs(t.normalized().z()), 1e-4) << p.image1 << "-" << p.image2;
    }
    const sfm::CaptureEvidence e = sfm::summarize_capture(g);
    EXPECT_TRUE(e.read);
    EXPECT_EQ(e.photos, 8);
    EXPECT_EQ(e.verified_pairs, 28);
    EXPECT_EQ(e.median_partners, 7);
    EXPECT_EQ(e.poorly_matched_photos, 0);
    EXPECT_EQ(e.strong_pairs, 28);
    EXPECT_EQ(e.forward_pairs, 28);  // sway of 5 cm against steps of 40 cm: within 8° of the axis
    EXPECT_EQ(e.default_start_pairs, 0);
    EXPECT_LT(e.median_forward_angle_deg, 8);
    EXPECT_EQ(e.sequential_photos, 8);  // with features found only within 12 units, neighbours share the most
    EXPECT_TRUE(e.forward);
    EXPECT_TRUE(sfm::is_forward_capture(e));
    EXPECT_CONTAINS(e.summary, "28 strong pairs");
  }
}

TEST(CaptureEvidence, AnOrbitIsNotAForwardWalk) {
  TempDir tmp;
  const fs::path db = tmp.path() / "orbit.db";
  write_database(db, orbit_poses(), street_points(600, 7), false);
  const sfm::CaptureEvidence e = sfm::summarize_capture(sfm::read_capture_geometry(db));
  EXPECT_TRUE(e.read);
  EXPECT_GT(e.strong_pairs, 10);
  EXPECT_EQ(e.forward_pairs, 0);        // the baselines of an arc are across the view
  EXPECT_GT(e.default_start_pairs, 0);  // photos 2+ steps apart meet at 25°+
  EXPECT_GT(e.median_forward_angle_deg, 45);
  EXPECT_FALSE(e.forward);
}

TEST(CaptureEvidence, TheRuleTurnsAtHalfTheStrongPairs) {
  sfm::CaptureEvidence e;
  e.read = true;
  e.strong_pairs = 10;
  e.forward_pairs = 5;
  EXPECT_TRUE(sfm::is_forward_capture(e));
  e.forward_pairs = 4;
  EXPECT_FALSE(sfm::is_forward_capture(e));
  e.strong_pairs = 0, e.forward_pairs = 0;
  EXPECT_FALSE(sfm::is_forward_capture(e));  // nothing to judge from
  e.strong_pairs = 10, e.forward_pairs = 10, e.read = false;
  EXPECT_FALSE(sfm::is_forward_capture(e));
}

TEST(CaptureEvidence, ADatabaseWithoutTheGeometryIsAnErrorNamingTheFile) {
  TempDir tmp;
  const fs::path db = tmp.path() / "bare.db";
  sqlite3* h = nullptr;
  ASSERT_EQ(sqlite3_open(db.c_str(), &h), SQLITE_OK);
  sqlite3_exec(h, "CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT)", nullptr, nullptr, nullptr);
  sqlite3_close(h);
  const std::string what = error_of<std::runtime_error>([&] { sfm::read_capture_geometry(db); });
  EXPECT_CONTAINS(what, db.string());
  EXPECT_CONTAINS(what, "not a colmap database");
}

// ---- The ladder, with the fake colmap ------------------------------------------------------

// A forward walk's database: the first mapper run already has the forward-walk thresholds, the
// log and the result say which evidence chose them, and metrics' record carries the evidence.
TEST_F(FakeColmap, AForwardWalkIsMappedWithForwardThresholdsFromTheFirstRun) {
  const fs::path db = tmp_.path() / "walk.db";
  std::vector<Pose> poses = walk_poses();
  poses.resize(6);  // the fixture's six photos
  write_database(db, poses, street_points(600, 5), false);
  ScopedEnv db_env("FAKE_COLMAP_DB", db.string());
  give_models({6});
  const sfm::SfmResult r = sfm::run_sfm(options_);
  ASSERT_EQ(r.attempts.size(), 1u);
  EXPECT_EQ(r.attempts[0].step, "forward walk");
  EXPECT_TRUE(r.capture.forward);
  EXPECT_EQ(r.capture.forward_pairs, 15);
  EXPECT_CONTAINS(r.mapper_reason, "forward walk: 15 of 15 strong pairs");
  const std::string args = slurp(args_log_);
  const std::string mapper = args.substr(args.find("\nmapper "));
  for (const char* option :
       {"--Mapper.init_min_tri_angle 2", "--Mapper.init_max_forward_motion 1.0", "--Mapper.tri_min_angle 0.5",
        "--Mapper.abs_pose_min_num_inliers 15", "--Mapper.init_min_num_inliers 50"})
    EXPECT_CONTAINS(mapper, option);
  const std::string log = slurp(r.log);
  EXPECT_CONTAINS(log, "capture evidence");
  EXPECT_CONTAINS(log, "mapper: forward walk");
  EXPECT_CONTAINS(sfm::describe_attempts(r), "capture: 6 photos, 15 verified pairs");
}

// Every photo left out has matches with at least two photos: after the cheap steps the ladder
// stops, says why and what to try, and never matches again; an orbit keeps colmap's defaults.
TEST_F(FakeColmap, TheLadderDoesNotMatchAgainWhenTheLostPhotosHaveMatches) {
  options_.escalate = true;
  options_.min_registered_share = 0.5;
  const fs::path db = tmp_.path() / "orbit.db";
  std::vector<Pose> poses = orbit_poses();
  poses.resize(6);
  write_database(db, poses, street_points(600, 7), false);
  ScopedEnv db_env("FAKE_COLMAP_DB", db.string());
  give_models({3});  // every mapper run and the registration place p0..p2
  const sfm::SfmResult r = sfm::run_sfm(options_);
  std::vector<std::string> steps;
  for (const auto& a : r.attempts) steps.push_back(a.step + " " + std::to_string(a.registered));
  EXPECT_EQ(steps, (std::vector<std::string>{"colmap defaults 3", "relaxed mapper 3", "register the rest 3"}));
  EXPECT_FALSE(r.capture.forward);
  EXPECT_CONTAINS(r.mapper_reason, "colmap's defaults");
  EXPECT_CONTAINS(r.escalation_stopped, "each of the 3 photo(s) not placed has verified matches");
  EXPECT_CONTAINS(r.escalation_stopped, "Try ");
  EXPECT_EQ(slurp(args_log_).find("guided_matching"), std::string::npos);
  std::istringstream lines(slurp(args_log_));
  int extractions = 0;
  for (std::string line; std::getline(lines, line);) extractions += line.rfind("feature_extractor ", 0) == 0;
  EXPECT_EQ(extractions, 1);  // no step extracted again
  EXPECT_CONTAINS(sfm::describe_attempts(r), "escalation stopped: each of the 3");
}

}  // namespace
}  // namespace desplat::testing::sfm_fixture
