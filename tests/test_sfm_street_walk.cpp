// Structure from motion with the real colmap on a forward walk down a synthetic street
// (data/synthetic/street_walk.json: 32 views at 640×480, cameras looking ahead as they walk, a
// few small passers-by): the capture evidence colmap's database gives recognises the walk, the
// first mapper run already has the forward-walk thresholds, and the ladder never matches again
// (every photo has verified matches). How many photos colmap's mapper then places differs from
// run to run on this scene (its RANSAC is not seeded), with these thresholds as with its
// defaults, so the test prints the placement and where the cameras landed and asserts neither.
// When the mapper places fewer than run_sfm's minimum of 4, run_sfm fails with the steps it
// took, and colmap.log holds the evidence and the mapper's choice: the same rules are checked
// there.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cerrno>
#include <cstdio>
#include <string>
#include <vector>

#include "desplat/io/colmap.hpp"
#include "desplat/sfm/sfm.hpp"
#include "desplat/synth/synth.hpp"
#include "support/expect.hpp"
#include "support/similarity.hpp"
#include "support/temp_dir.hpp"

namespace desplat::testing {
namespace {

namespace fs = std::filesystem;

Eigen::Vector3d centre(const colmap::Image& im) {
  const auto& q = im.qvec_wxyz;
  const Eigen::Matrix3d R = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  return -R.transpose() * Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]);
}

// Photos of `model` also in `truth`, by name: their centres as 3×n matrices (model, truth).
std::pair<Eigen::Matrix3Xd, Eigen::Matrix3Xd> shared_centres(const colmap::Model& model, const colmap::Model& truth) {
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pairs;
  for (const auto& [id, im] : model.images)
    for (const auto& [tid, t] : truth.images)
      if (t.name == im.name) pairs.emplace_back(centre(im), centre(t));
  Eigen::Matrix3Xd a(3, pairs.size()), b(3, pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) a.col(i) = pairs[i].first, b.col(i) = pairs[i].second;
  return {a, b};
}

TEST(SfmStreetWalk, AForwardWalkGetsTheForwardThresholdsFromTheFirstRunAndIsNeverMatchedAgain) {
  ASSERT_TRUE(sfm::find_executable("colmap")) << "colmap is not on PATH: run scripts/install_deps.sh";
  errno = 0;
  (void)::nice(10);  // colmap inherits it: a shared machine's other work keeps moving
  TempDir tmp("street_walk");
  const fs::path scene = tmp.path() / "scene";
  const synth::Description d =
      synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/street_walk.json");
  ASSERT_GE(d.camera.width, 640);
  ASSERT_GE(d.camera.height, 480);
  ASSERT_GE(d.views.count, 30);
  synth::generate_scene(d, {scene, false, {}});

  sfm::SfmOptions o;
  o.images = scene / "images";
  o.out = tmp.path() / "sfm";
  o.num_threads = 2;
  o.min_registered_share = 0.1;  // a short model is reported here, not thrown
  const int n = d.views.count;
  sfm::SfmResult r;
  try {
    r = sfm::run_sfm(o);
  } catch (const sfm::SfmError& e) {
    ASSERT_TRUE(e.kind() == sfm::SfmErrorKind::TooFewRegistered || e.kind() == sfm::SfmErrorKind::NoModel) << e.what();
    const std::string what = e.what(), log = slurp(o.out / "colmap.log");
    EXPECT_CONTAINS(log, "desplat_sfm: mapper: forward walk");
    EXPECT_CONTAINS(log, "0 photo(s) with fewer than 2 partners of 30 inliers");
    EXPECT_CONTAINS(log, ", 0 could start colmap's default mapper");
    int strong = 0, forward = 0;
    const size_t at = log.find(" strong pairs (>= 100 inliers): ");
    ASSERT_NE(at, std::string::npos) << log;
    const size_t from = log.rfind(' ', at - 1) + 1;
    ASSERT_EQ(std::sscanf(log.c_str() + from, "%d strong pairs (>= 100 inliers): %d move within", &strong, &forward), 2)
        << log.substr(from, 120);
    EXPECT_GE(forward, 0.9 * strong);
    if (e.kind() == sfm::SfmErrorKind::TooFewRegistered) {
      EXPECT_CONTAINS(what, "Photos placed by each step: forward walk ");
      EXPECT_CONTAINS(what, "cannot help");
    }
    // The steps taken (the reason the ladder stopped names the matching steps it skipped).
    const size_t list = what.find("Photos placed by each step: ");
    const std::string steps = list == std::string::npos ? "" : what.substr(list, what.find('.', list) - list);
    EXPECT_EQ(steps.find("guided matching"), std::string::npos) << steps;
    EXPECT_EQ(steps.find("more features"), std::string::npos) << steps;
    std::printf("street walk: the mapper placed too few this run\n%s\n", what.c_str());
    return;
  }

  // The evidence: (nearly) every strong pair moves along the viewing direction, and none meets
  // the start test of colmap's defaults.
  EXPECT_TRUE(r.capture.read) << r.capture.summary;
  EXPECT_TRUE(r.capture.forward) << r.capture.summary;
  EXPECT_GE(r.capture.forward_pairs, 0.9 * r.capture.strong_pairs) << r.capture.summary;
  EXPECT_EQ(r.capture.poorly_matched_photos, 0) << r.capture.summary;
  EXPECT_EQ(r.capture.default_start_pairs, 0) << r.capture.summary;
  EXPECT_CONTAINS(r.mapper_reason, "forward walk");
  ASSERT_FALSE(r.attempts.empty());
  EXPECT_EQ(r.attempts[0].step, "forward walk");
  for (const sfm::SfmAttempt& a : r.attempts) {
    EXPECT_NE(a.step, "guided matching") << sfm::describe_attempts(r);
    EXPECT_NE(a.step, "more features") << sfm::describe_attempts(r);
  }
  if (r.num_registered < sfm::kEscalateBelowShare * n) EXPECT_CONTAINS(r.escalation_stopped, "cannot help");

  // Where the generator put the cameras, up to a similarity (tests/test_sfm_real.cpp's measure).
  const colmap::Model ours = colmap::read_model_binary(r.sparse_dir);
  const colmap::Model truth = colmap::read_model_binary(scene / "sparse" / "0");
  const auto [a, b] = shared_centres(ours, truth);
  ASSERT_EQ(a.cols(), r.num_registered);
  std::printf("street walk: %d of %d placed (%s); camera-centre alignment error %.4f of the spread\n%s",
              r.num_registered, n, r.attempts[0].step.c_str(), relative_alignment_error(a, b),
              sfm::describe_attempts(r).c_str());
}

}  // namespace
}  // namespace desplat::testing
