// Transient sparse points (docs/METHOD.md §5): the per-point rule against hand-computed
// cases, the tracks the scene loader reports against the observations in images.bin (written
// by COLMAP), and what each action does to the initialization.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "desplat/io/colmap.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/trainer.hpp"
#include "desplat/train/transient_points.hpp"
#include "support/expect.hpp"
#include "support/projection.hpp"
#include "support/scene_fixtures.hpp"
#include "support/synthetic_views.hpp"

namespace desplat {
namespace {

// A 4×4 view at the origin looking along +z, f = 4, principal point at the centre: the world
// point (0, 0, 1) lands on pixel (2, 2). All grey 0.5, except `bright` at pixel (2, 2).
TrainView tiny_view(float bright) {
  TrainView v;
  v.name = "v";
  v.camera.width = v.camera.height = 4;
  v.camera.fx = v.camera.fy = 4;
  v.camera.cx = v.camera.cy = 2;
  FloatImage photo{4, 4, 3, std::vector<float>(48, 0.5f)};
  for (int c = 0; c < 3; ++c) photo.pixels[3 * (2 * 4 + 2) + c] = bright;
  v.image = to_bytes(photo);  // 0.5 becomes 128
  return v;
}

TEST(TransientPoints, ShortTracksAndDisagreeingColours) {
  TrainingData d;
  d.train = {tiny_view(0.5f), tiny_view(1.0f)};
  const std::array<uint8_t, 3> grey{128, 128, 128};  // 0.502
  // 0: 5 images, seen by view 0 (grey there): static.
  // 1: 5 images, seen by views 0 and 1; view 1 is white there: |1 − 0.502| = 0.498 > 0.25.
  // 2: a track of 2 images: transient whatever its colour.
  // 3: behind the cameras, seen by view 1: no colour to compare, static.
  // 4: projects outside the image (u = 4·3/1 + 2 = 14): static.
  d.points = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, -1}, {3, 0, 1}};
  d.colors = {grey, grey, grey, grey, grey};
  d.point_track_images = {5, 5, 2, 5, 5};
  d.point_train_views = {{0}, {0, 1}, {0}, {1}, {1}};
  TransientPointSettings s;
  EXPECT_EQ(transient_points(d, s), (std::vector<uint8_t>{0, 1, 1, 0, 0}));
  s.min_track_images = 2;
  EXPECT_EQ(transient_points(d, s), (std::vector<uint8_t>{0, 1, 0, 0, 0}));
  s.color_tolerance = 0.5f;  // 0.498 is within it
  EXPECT_EQ(transient_points(d, s), (std::vector<uint8_t>{0, 0, 0, 0, 0}));

  // Without tracks (not from a COLMAP model) nothing is transient; half a track is an error.
  TrainingData no_tracks = d;
  no_tracks.point_track_images.clear();
  no_tracks.point_train_views.clear();
  EXPECT_EQ(transient_points(no_tracks, TransientPointSettings{}), std::vector<uint8_t>(5, 0));
  no_tracks.point_track_images = {5};
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { transient_points(no_tracks, {}); }),
                  "does not match the points");
  TrainingData bad_view = d;
  bad_view.point_train_views[0] = {7};
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { transient_points(bad_view, {}); }), "does not exist");
}

// Two photos of one grey wall taken two stops apart: 0.225 and 0.9 everywhere. Each of 40
// points (one per pixel of the top five rows) has COLMAP's mean colour 143/255 = 0.561, which
// differs from both photos by more than 0.25 (0.337 and 0.341): compared as stored, every point
// disagrees. Each view's gain (the median photo / point ratio over its 40 samples: 57/143 and
// 230/143) maps 0.561 onto the photo exactly, so after it no point disagrees, except point 40,
// on the bottom-right pixel, which view 1 shows dark (0.2 where 0.9 is expected): a transient.
TEST(TransientPoints, ColoursAreComparedAfterEachViewsExposure) {
  auto wall = [](float grey) {
    TrainView v;
    v.name = "wall";
    v.camera.width = v.camera.height = 8;
    v.camera.fx = v.camera.fy = 8;
    v.camera.cx = v.camera.cy = 4;
    v.image = to_bytes(FloatImage{8, 8, 3, std::vector<float>(192, grey)});
    return v;
  };
  TrainingData d;
  d.train = {wall(0.225f), wall(0.9f)};
  for (int c = 0; c < 3; ++c) d.train[1].image.pixels[3 * 63 + c] = 51;  // 0.2 at pixel (7, 7)
  auto point_at = [](int u, int v) { return std::array<float, 3>{(u + 0.5f - 4) / 8, (v + 0.5f - 4) / 8, 1}; };
  for (int v = 0; v < 5; ++v)
    for (int u = 0; u < 8; ++u) d.points.push_back(point_at(u, v));
  d.points.push_back(point_at(7, 7));
  const size_t n = d.points.size();
  d.colors.assign(n, {143, 143, 143});
  d.point_track_images.assign(n, 5);
  d.point_train_views.assign(n, {0, 1});
  ASSERT_EQ(d.train[0].camera.pixel_of(d.points[40]), 63);

  const std::vector<std::array<float, 3>> gains = view_gains(d);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(gains[0][c], 57.0 / 143.0, 1e-5);
    EXPECT_NEAR(gains[1][c], 230.0 / 143.0, 1e-5);
  }
  std::vector<uint8_t> only_the_dark_pixel(n, 0);
  only_the_dark_pixel[40] = 1;
  TransientPointSettings s;
  EXPECT_EQ(transient_points(d, s), only_the_dark_pixel);
  s.per_view_gain = false;
  EXPECT_EQ(transient_points(d, s), std::vector<uint8_t>(n, 1));
  s.per_view_gain = true;
  EXPECT_EQ(
      config_from_json(nlohmann::json{{"init", {{"transient_per_view_gain", false}}}}).transient_points.per_view_gain,
      false);

  // Fewer than 30 samples per channel: no evidence of a gain, the colour is compared as stored.
  TrainingData few = d;
  few.points.resize(20);
  few.colors.resize(20);
  few.point_track_images.resize(20);
  few.point_train_views.resize(20);
  EXPECT_EQ(view_gains(few), (std::vector<std::array<float, 3>>(2, {1.0f, 1.0f, 1.0f})));
  EXPECT_EQ(transient_points(few, s), std::vector<uint8_t>(20, 1));
}

TEST(TransientPoints, ConfigNamesTheActionAndRejectsOthers) {
  TrainConfig c;
  c.transient_points.action = TransientPointAction::seed;
  const nlohmann::json j = config_to_json(c);
  EXPECT_EQ(j["init"]["transient_points"], "seed");
  EXPECT_EQ(config_from_json(j).transient_points.action, TransientPointAction::seed);
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] {
                    config_from_json(nlohmann::json{{"init", {{"transient_points", "bury"}}}});
                  }),
                  "init.transient_points must be keep, drop or seed");
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] {
                    config_from_json(nlohmann::json{{"init", {{"transient_points", 2}}}});
                  }),
                  "init.transient_points must be a string");
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] {
                    config_from_json(nlohmann::json{{"init", {{"transient_min_track_images", -1}}}});
                  }),
                  "init.transient_min_track_images");
}

TEST(TransientPoints, FoxTracksMatchTheObservationsInImagesBin) {
  // The loader reads tracks from points3D.bin; the same facts, seen from images.bin: every
  // observation with a 3D point names the image that sees it.
  scene_test::Warnings w;
  testing::TempDir cache("fox_tracks");
  const Scene scene = load_colmap_scene(scene_test::kFox, scene_test::quiet_options(cache.path(), w));
  const colmap::Model model = colmap::read_model(scene_test::kFox / "sparse/0");
  std::map<uint64_t, std::set<uint32_t>> views_of_point;
  for (size_t v = 0; v < scene.views.size(); ++v)
    for (const colmap::Observation& o : model.images.at(scene.views[v].colmap_image_id).points2d)
      if (o.point3d_id != colmap::kNoPoint3D) views_of_point[uint64_t(o.point3d_id)].insert(uint32_t(v));
  ASSERT_EQ(scene.point_views.size(), scene.point_ids.size());
  ASSERT_EQ(scene.point_track_images.size(), scene.point_ids.size());
  size_t short_tracks = 0;
  for (size_t i = 0; i < scene.point_ids.size(); ++i) {
    const std::set<uint32_t>& expected = views_of_point[scene.point_ids[i]];
    EXPECT_EQ(std::vector<uint32_t>(expected.begin(), expected.end()), scene.point_views[i]) << scene.point_ids[i];
    EXPECT_EQ(scene.point_track_images[i], expected.size());  // every fox image is used by the default split
    short_tracks += expected.size() < 3;
  }
  EXPECT_GT(short_tracks, 0u);  // COLMAP keeps two-image tracks: the rule has something to judge
}

TEST(TransientPoints, DropLeavesThePointOutAndSeedMovesItIntoItsView) {
  // Point 0 gets a one-image track in training view 0; every other point is seen by all views.
  TrainingData data = test::synthetic_training_data(8, 64, 48, 5);
  const size_t n = data.points.size();
  data.point_track_images.assign(n, 8);
  data.point_train_views.assign(n, {});
  for (size_t i = 0; i < n; ++i)
    for (int v = 0; v < int(data.train.size()); ++v) data.point_train_views[i].push_back(v);
  data.point_track_images[0] = 1;
  data.point_train_views[0] = {0};
  // Where point 0 lands in view 0 (it must, for the seed test to mean anything).
  const Camera& cam = data.train[0].camera;
  const auto [u0, v0, z0] = test::project_point(cam, data.points[0]);
  ASSERT_GT(z0, 0);
  ASSERT_TRUE(u0 >= 0 && v0 >= 0 && u0 < 64 && v0 < 48);

  std::map<TransientPointAction, std::pair<size_t, size_t>> sizes;  // static, view 0's distractors
  for (const TransientPointAction a :
       {TransientPointAction::keep, TransientPointAction::drop, TransientPointAction::seed}) {
    TrainConfig c;
    c.transient_points.action = a;
    c.transient_points.color_tolerance = 1.0f;  // only the track length decides here
    c.distractors.initial_count = 50;
    c.distractors.reference_pixels = 0;
    c.threads = 1;
    Trainer t(data, c);
    sizes[a] = {t.gaussians().size(), t.distractors()[0].size()};
    EXPECT_EQ(t.transient_point_count, a == TransientPointAction::keep ? 0 : 1);
    if (a == TransientPointAction::seed) {
      ASSERT_EQ(t.transient_seeded, 1);
      const GaussianSet& d = t.distractors()[0].params;
      const auto [u, v, z] = test::project_mean(cam, d, d.size() - 1);  // the seed is appended last
      EXPECT_EQ(int(u), int(u0));
      EXPECT_EQ(int(v), int(v0));
      for (size_t w = 1; w < t.distractors().size(); ++w) EXPECT_EQ(t.distractors()[w].size(), 50u);
    }
  }
  // Without distractors the model is the Splatfacto baseline: every point, whatever the action.
  TrainConfig baseline;
  baseline.distractors.enabled = false;
  baseline.transient_points.action = TransientPointAction::drop;
  baseline.threads = 1;
  const Trainer static_only(data, baseline);
  EXPECT_EQ(static_only.gaussians().size(), n);
  EXPECT_EQ(static_only.transient_point_count, 0);
  EXPECT_EQ(static_only.config().transient_points.action, TransientPointAction::keep);

  EXPECT_EQ(sizes[TransientPointAction::keep], (std::pair<size_t, size_t>{n, 50}));
  EXPECT_EQ(sizes[TransientPointAction::drop], (std::pair<size_t, size_t>{n - 1, 50}));
  EXPECT_EQ(sizes[TransientPointAction::seed], (std::pair<size_t, size_t>{n - 1, 51}));
}

}  // namespace
}  // namespace desplat
