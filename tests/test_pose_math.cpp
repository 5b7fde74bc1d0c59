// The project's own camera and pose math against independent implementations of the same
// conventions: the synthetic views' look-at (Eigen, src/synth/camera_path.cpp) against
// glm::lookAt; the rotation → quaternion the generator writes to images.bin (GLM,
// synth::quaternion_of) against a brute-force rotation check and against Eigen's
// Quaternion(Matrix3), whose bits every scene generated so far holds; and the quaternion →
// rotation the scene loader builds each Camera from (Eigen, src/io/scene_loader.cpp) against
// glm::mat3_cast.
//
// Conventions (docs/METHOD.md §1): COLMAP's camera looks along +z with x right and y down;
// GLM's look-at is OpenGL's, looking along −z with y up, so R_colmap = diag(1, −1, −1)·R_gl and
// t_colmap = diag(1, −1, −1)·t_gl. GLM is column-major: M[c][r] is row r, column c.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstring>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_access.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <map>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "desplat/io/colmap.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/synth/synth.hpp"
#include "support/temp_dir.hpp"
#include "synth/camera_path.hpp"

namespace fs = std::filesystem;
using namespace desplat;

namespace {

// COLMAP's world-to-camera pose from GLM's view matrix.
struct ColmapPose {
  glm::dmat3 R;
  glm::dvec3 t;
};
ColmapPose glm_look_at(const glm::dvec3& eye, const glm::dvec3& target, const glm::dvec3& up) {
  const glm::dmat4 view = glm::lookAtRH(eye, target, up);
  const glm::dmat3 flip(glm::dvec3(1, 0, 0), glm::dvec3(0, -1, 0), glm::dvec3(0, 0, -1));
  return {flip * glm::dmat3(view), flip * glm::dvec3(view[3])};
}

glm::dvec3 to_glm(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// A generated 64×48, 8-view orbit (the default description) in a temporary folder.
struct TinyScene {
  desplat::testing::TempDir dir;
  synth::Description description;
  TinyScene() {
    synth::GenerateOptions o;
    o.out = dir.path() / "scene";
    synth::generate_scene(description, o);
  }
};

// Rotations that reach every branch of quaternion_of: random ones (mostly trace > 0), half
// turns about each axis and about random axes (trace −1, each diagonal entry the largest in
// turn), and turns by nearly π, where the trace is just above or below zero.
std::vector<glm::dmat3> test_rotations() {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal;
  std::vector<glm::dmat3> out;
  const auto axis_angle = [](glm::dvec3 axis, double angle) {
    // Rodrigues: R = cos θ·I + sin θ·[a]× + (1 − cos θ)·a·aᵀ, column-major.
    const glm::dvec3 a = axis / std::sqrt(glm::dot(axis, axis));
    const glm::dmat3 skew(glm::dvec3(0, a.z, -a.y), glm::dvec3(-a.z, 0, a.x), glm::dvec3(a.y, -a.x, 0));
    return std::cos(angle) * glm::dmat3(1.0) + std::sin(angle) * skew + (1 - std::cos(angle)) * glm::outerProduct(a, a);
  };
  for (const glm::dvec3 axis : {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)})
    out.push_back(axis_angle(axis, std::numbers::pi));
  for (int k = 0; k < 20000; ++k) {
    const glm::dvec3 axis(normal(rng), normal(rng), normal(rng));
    const double angle = k % 4 == 0   ? std::numbers::pi
                         : k % 4 == 1 ? 2.0943951 + 1e-3 * normal(rng)
                                      : 3.2 * normal(rng);
    out.push_back(axis_angle(axis, angle));
  }
  return out;
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

}  // namespace

// The quaternion's rotation is the matrix it came from, the quaternion is unit length, and
// every branch (w, x, y or z largest) is taken.
TEST(PoseMath, QuaternionOfARotationRotatesAsTheMatrixDoes) {
  int branch[4] = {};
  for (const glm::dmat3& R : test_rotations()) {
    const glm::dquat q = synth::quaternion_of(R);
    EXPECT_NEAR(glm::length(q), 1.0, 1e-14);
    // q rotates a vector as R does: v' = q·v·q*, written out with the Hamilton product.
    for (const glm::dvec3 v : {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)}) {
      const glm::dvec3 u(q.x, q.y, q.z);
      const glm::dvec3 rotated = v + 2.0 * q.w * glm::cross(u, v) + 2.0 * glm::cross(u, glm::cross(u, v));
      const glm::dvec3 expected = R * v;
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(rotated[a], expected[a], 1e-14);
    }
    const double trace = R[0][0] + R[1][1] + R[2][2];
    const int largest = trace > 0 ? 0 : R[1][1] > std::max(R[0][0], R[2][2]) ? 2 : R[2][2] > R[0][0] ? 3 : 1;
    ++branch[largest];
  }
  for (int b = 0; b < 4; ++b) EXPECT_GT(branch[b], 100) << "branch " << b;
}

// images.bin keeps the bits of the scenes generated so far, which Eigen's Quaternion(Matrix3)
// wrote: every component is bit for bit Eigen's.
TEST(PoseMath, QuaternionOfIsEigensQuaternionBitForBit) {
  for (const glm::dmat3& R : test_rotations()) {
    Eigen::Matrix3d E;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) E(r, c) = R[c][r];
    const Eigen::Quaterniond expected(E);
    const glm::dquat q = synth::quaternion_of(R);
    ASSERT_TRUE(same_bits(q.w, expected.w()) && same_bits(q.x, expected.x()) && same_bits(q.y, expected.y()) &&
                same_bits(q.z, expected.z()))
        << "(" << q.w << ", " << q.x << ", " << q.y << ", " << q.z << ") vs Eigen's (" << expected.w() << ", "
        << expected.x() << ", " << expected.y() << ", " << expected.z() << ")";
  }
}

TEST(PoseMath, SynthLookAtIsGlmLookAtInColmapAxes) {
  const glm::dvec3 z_up(0, 0, 1), y_up(0, 1, 0);
  struct Case {
    Eigen::Vector3d center, target;
    glm::dvec3 up;  // look_at's choice: world z, or world y when looking (nearly) straight up or down
  };
  const Case cases[] = {{{4, 0, 2.5}, {0, 0, 0.3}, z_up},
                        {{-1.5, 3.2, 0.4}, {0.2, -0.1, 0.5}, z_up},
                        {{0.3, -7, -2}, {0, 0, 0}, z_up},
                        {{0.001, 0.002, 5}, {0, 0, 0}, y_up},
                        {{0, 0, -3}, {0, 0, 1}, y_up}};
  for (const Case& c : cases) {
    const synth::ViewPose ours = synth::look_at(c.center, c.target);
    const ColmapPose expected = glm_look_at(to_glm(c.center), to_glm(c.target), c.up);
    for (int r = 0; r < 3; ++r) {
      for (int col = 0; col < 3; ++col)
        EXPECT_NEAR(ours.R_cw(r, col), expected.R[col][r], 1e-12) << "R(" << r << "," << col << ")";
      EXPECT_NEAR(ours.t_cw[r], expected.t[r], 1e-12) << "t[" << r << "]";
      EXPECT_EQ(ours.center[r], c.center[r]);
    }
  }
}

// What the generator wrote, read back through GLM's quaternion → rotation: every camera sits on
// the described orbit, looks at the target, and keeps world z up in its image.
TEST(PoseMath, SyntheticCamerasStoredInImagesBinLookAtTheTargetFromTheOrbit) {
  const TinyScene scene;
  const synth::ViewsSpec& v = scene.description.views;
  const glm::dvec3 target(v.target[0], v.target[1], v.target[2]);
  const colmap::Model model = colmap::read_model(scene.dir.path() / "scene" / "sparse" / "0");
  ASSERT_EQ(model.images.size(), size_t(v.count));
  for (const auto& [id, image] : model.images) {
    SCOPED_TRACE(image.name);
    const auto [w, x, y, z] = image.qvec_wxyz;
    const glm::dquat q(w, x, y, z);
    EXPECT_NEAR(glm::length(q), 1.0, 1e-12);
    const glm::dmat3 R = glm::mat3_cast(q);
    const glm::dvec3 t(image.tvec[0], image.tvec[1], image.tvec[2]);
    const glm::dvec3 center = -(glm::transpose(R) * t);
    EXPECT_NEAR(glm::length(glm::dvec2(center - target)), v.radius, 1e-9);  // horizontal distance
    EXPECT_NEAR(center.z - target.z, v.height, 1e-9);
    const glm::dvec3 forward = glm::row(R, 2), right = glm::row(R, 0), down = glm::row(R, 1);
    const glm::dvec3 to_target = glm::normalize(target - center);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(forward[a], to_target[a], 1e-9);
    EXPECT_NEAR(right.z, 0.0, 1e-9);  // the horizon is level
    EXPECT_LT(down.z, 0.0);           // image down is world down
  }
}

// The scene loader's Camera: the normalized quaternion's rotation (rounded to float) and the
// camera centre moved into the normalized frame.
TEST(PoseMath, SceneLoaderCamerasAreTheColmapQuaternionsRotationAndCentre) {
  const TinyScene scene;
  const fs::path data = scene.dir.path() / "scene";
  const colmap::Model model = colmap::read_model(data / "sparse" / "0");
  std::map<std::string, const colmap::Image*> by_name;
  for (const auto& [id, image] : model.images) by_name[image.name] = &image;
  SceneOptions o;
  o.cache_dir = scene.dir.path() / "cache";
  const Scene loaded = load_colmap_scene(data, o);
  ASSERT_EQ(loaded.views.size(), model.images.size());
  for (const SceneView& view : loaded.views) {
    SCOPED_TRACE(view.name);
    const colmap::Image& image = *by_name.at(view.name);
    const auto [w, x, y, z] = image.qvec_wxyz;
    const glm::dmat3 R = glm::mat3_cast(glm::normalize(glm::dquat(w, x, y, z)));
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(view.camera.R_cw[3 * r + c], R[c][r], 1e-7) << r << "," << c;
    const glm::dvec3 center = -(glm::transpose(R) * glm::dvec3(image.tvec[0], image.tvec[1], image.tvec[2]));
    const std::array<double, 3> expected = loaded.normalization.to_normalized({center.x, center.y, center.z});
    const std::array<float, 3> ours = view.camera.center();
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(ours[a], expected[a], 1e-5);
  }
}
