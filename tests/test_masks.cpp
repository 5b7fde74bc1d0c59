// Distractor masks (io/masks.hpp): scoring against hand-counted cases, and mask discovery and
// loading through the same resize + undistortion as the photos, on a small capture with a
// strongly distorted OPENCV lens written here.
//
// Independent expectations: hand-counted IoUs; an image whose pixel values equal its mask's,
// which must come out of load_view_image with the same values as load_view_mask; keypoint
// mapping (undistort_pixel) for where a mask blob lands.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>

#include "desplat/io/colmap.hpp"
#include "desplat/io/masks.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/io/undistort.hpp"
#include "desplat/jobs/training_run.hpp"
#include "support/expect.hpp"
#include "support/look_at.hpp"
#include "support/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using colmap::CameraModelId;
using desplat::testing::error_of;
using desplat::testing::slurp;
using desplat::testing::TempDir;

namespace {

// ---- score_mask ----------------------------------------------------------------------------------

TEST(ScoreMask, HandCountedCase) {
  //                         P: 1    1    0    0 (not > 0.5)  0    1
  const std::vector<float> predicted{0.9f, 0.6f, 0.2f, 0.5f, 0.0f, 1.0f};
  //                         T: 1    0    1    1    0    1
  const std::vector<float> truth{1.0f, 0.0f, 1.0f, 1.0f, 0.0f, 0.51f};
  const MaskScore s = score_mask(predicted, truth);
  EXPECT_DOUBLE_EQ(s.iou, 2.0 / 5.0);  // P∩T = {0, 5}, P∪T = {0, 1, 2, 3, 5}
  EXPECT_DOUBLE_EQ(s.predicted_fraction, 3.0 / 6.0);
  EXPECT_DOUBLE_EQ(s.truth_fraction, 4.0 / 6.0);
  // A lower threshold adds pixels 2 and 3 to P: P∩T = {0, 2, 3, 5}, P∪T unchanged.
  EXPECT_DOUBLE_EQ(score_mask(predicted, truth, 0.1f).iou, 4.0 / 5.0);
}

TEST(ScoreMask, EmptyAndDisjoint) {
  const std::vector<float> zeros(12, 0.0f), ones(12, 1.0f);
  const MaskScore empty = score_mask(zeros, zeros);
  EXPECT_EQ(empty.iou, 1.0);  // nothing to find, nothing found
  EXPECT_EQ(empty.predicted_fraction, 0.0);
  EXPECT_EQ(empty.truth_fraction, 0.0);
  EXPECT_EQ(score_mask({}, {}).iou, 1.0);
  const MaskScore missed = score_mask(zeros, ones);
  EXPECT_EQ(missed.iou, 0.0);
  EXPECT_EQ(missed.truth_fraction, 1.0);
  const MaskScore false_alarm = score_mask(ones, zeros);  // a clean view: the FP area is the signal
  EXPECT_EQ(false_alarm.iou, 0.0);
  EXPECT_EQ(false_alarm.predicted_fraction, 1.0);
}

TEST(ScoreMask, SizeMismatchThrows) {
  const std::vector<float> a(6, 0.0f), b(7, 0.0f);
  EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { score_mask(a, b); }), "7");
}

// ---- Mask discovery and loading on a distorted capture --------------------------------------------

constexpr int kW = 64, kH = 48;

// Three cameras on a ring looking at the origin through a strongly distorted OPENCV lens.
colmap::Model distorted_model() {
  colmap::Model m;
  m.cameras[1] = colmap::Camera{1, CameraModelId::OpenCV, kW, kH, {50.0, 52.0, 31.0, 25.0, -0.25, 0.05, 0.002, -0.003}};
  for (int i = 0; i < 3; ++i) {
    const double a = 0.4 * i;
    const Eigen::Vector3d C(3 * std::sin(a), 0.1 * i, -3 * std::cos(a));
    const colmap::Image im = desplat::testing::look_at_origin(C, uint32_t(i + 1), "view_" + std::to_string(i) + ".png");
    m.images[im.id] = im;
  }
  colmap::Point3D p;
  p.id = 1;
  m.points[1] = p;
  return m;
}

// Grey levels k/255 with sharp steps and gradients in both directions (no symmetry that
// would hide a flipped or shifted resampling).
FloatImage grey_pattern(int seed) {
  FloatImage g{kW, kH, 1, std::vector<float>(kW * kH)};
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) g.pixels[y * kW + x] = float((x * 7 + y * y * 3 + seed * 41) % 256) / 255.0f;
  return g;
}

FloatImage as_rgb(const FloatImage& grey) {
  FloatImage rgb{grey.width, grey.height, 3, {}};
  for (float v : grey.pixels) rgb.pixels.insert(rgb.pixels.end(), {v, v, v});
  return rgb;
}

// A mask file in another bit depth and channel layout: 16-bit, channel 0 = the values, channel
// 1 = noise that must be ignored.
void write_mask_16bit_two_channels(const fs::path& path, const FloatImage& grey) {
  std::vector<uint16_t> px;
  for (size_t i = 0; i < grey.pixels.size(); ++i)
    px.insert(px.end(), {uint16_t(std::lround(grey.pixels[i] * 65535.0f)), uint16_t((i * 7919) % 65536)});
  OIIO::ImageSpec spec(grey.width, grey.height, 2, OIIO::TypeDesc::UINT16);
  spec.attribute("oiio:UnassociatedAlpha", 1);  // PNG stores channel 1 as alpha: keep channel 0 as given
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, px.data()) && out->close());
}

struct MaskedCapture {
  TempDir dir{"masks_capture"};
  TempDir cache{"masks_cache"};
  std::vector<FloatImage> patterns;
};

// Every view's photo is RGB = its mask's grey values; view 2 has no mask file, view 1's is 16-bit.
void write_masked_capture(MaskedCapture& c, bool with_masks = true) {
  const colmap::Model m = distorted_model();
  colmap::write_model_binary(m, c.dir.path() / "sparse/0");
  for (const auto& [id, im] : m.images) {
    c.patterns.push_back(grey_pattern(int(id)));
    write_image(c.dir.path() / "images" / im.name, as_rgb(c.patterns.back()));
  }
  if (!with_masks) return;
  write_image(c.dir.path() / "distractor_masks/view_0.png", c.patterns[0]);
  write_mask_16bit_two_channels(c.dir.path() / "distractor_masks/view_1.png", c.patterns[1]);
}

SceneOptions all_train(const fs::path& cache, int downscale) {
  SceneOptions o;
  o.downscale = downscale;
  o.cache_dir = cache;
  o.split.rule = SplitRule::AllTrain;
  o.on_warning = [](const std::string&) {};
  return o;
}

TEST(LoadViewMask, DiscoversMasksByName) {
  MaskedCapture c;
  write_masked_capture(c);
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  ASSERT_EQ(scene.views.size(), 3u);
  EXPECT_EQ(scene.views[0].mask_path, scene.data_dir / "distractor_masks/view_0.png");
  EXPECT_EQ(scene.views[1].mask_path, scene.data_dir / "distractor_masks/view_1.png");
  EXPECT_TRUE(scene.views[2].mask_path.empty());  // folder present, file absent: no mask
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_mask(scene, 2); }), "view_2.png");
  EXPECT_EQ(distractor_mask_path("/d", "cam0/a.b.JPG"), fs::path("/d/distractor_masks/cam0/a.b.png"));
}

TEST(LoadViewMask, NoFolderMeansNoMasks) {
  MaskedCapture c;
  write_masked_capture(c, /*with_masks=*/false);
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  for (const SceneView& v : scene.views) EXPECT_TRUE(v.mask_path.empty()) << v.name;
}

// The photo (8-bit PNG, through the PNG cache) and the mask (float, not cached) go through
// the same INTER_AREA resize and bilinear remap, per channel, in float. The only difference is
// the cache's 8-bit rounding of the photo, ≤ 0.5/255; 1e-5 covers float summation order.
TEST(LoadViewMask, MatchesThePhotoPixelForPixel) {
  MaskedCapture c;
  write_masked_capture(c);
  for (int downscale : {1, 2}) {
    const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), downscale));
    for (size_t view : {size_t(0), size_t(1)}) {
      const FloatImage photo = load_view_image(scene, view);
      const FloatImage mask = load_view_mask(scene, view);
      ASSERT_EQ(mask.channels, 1);
      ASSERT_EQ(mask.width, scene.views[view].camera.width);
      ASSERT_EQ(mask.height, scene.views[view].camera.height);
      ASSERT_EQ(mask.width, photo.width);
      ASSERT_EQ(mask.height, photo.height);
      // The lens really resamples: the undistorted size is not the photo's size.
      EXPECT_NE(mask.width * downscale, kW) << "downscale " << downscale;
      float worst = 0;
      for (size_t p = 0; p < mask.pixels.size(); ++p)
        worst = std::max(worst, std::abs(mask.pixels[p] - photo.pixels[3 * p]));
      EXPECT_LE(worst, 0.5f / 255 + 1e-5f) << "view " << view << " downscale " << downscale;
    }
  }
}

// A small blob lands where keypoints go (undistort_pixel), independently of image resampling.
TEST(LoadViewMask, BlobFollowsTheKeypointMapping) {
  MaskedCapture c;
  write_masked_capture(c);
  FloatImage blob{kW, kH, 1, std::vector<float>(kW * kH, 0.0f)};
  const int bx = 46, by = 12;  // 3×3 blob centered on pixel (46, 12): COLMAP position (46.5, 12.5)
  for (int y = by - 1; y <= by + 1; ++y)
    for (int x = bx - 1; x <= bx + 1; ++x) blob.pixels[y * kW + x] = 1.0f;
  write_image(c.dir.path() / "distractor_masks/view_0.png", blob);
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  const FloatImage m = load_view_mask(scene, 0);
  double sum = 0, sx = 0, sy = 0;
  for (int y = 0; y < m.height; ++y)
    for (int x = 0; x < m.width; ++x) {
      const double v = m.pixels[size_t(y) * m.width + x];
      sum += v, sx += v * (x + 0.5), sy += v * (y + 0.5);
    }
  const SceneView& v = scene.views[0];
  const Vec2 expected = undistort_pixel(v.distorted_camera, v.undistorted_camera, {bx + 0.5, by + 0.5});
  ASSERT_GT(sum, 0.0);
  // Bilinear resampling of a 3-pixel blob under a locally affine warp keeps its centroid to
  // a small fraction of a pixel; 0.25 px still tells a half-pixel convention error apart.
  EXPECT_NEAR(sx / sum, expected[0], 0.25);
  EXPECT_NEAR(sy / sum, expected[1], 0.25);
}

TEST(LoadViewMask, BadMasksNameTheFile) {
  MaskedCapture c;
  write_masked_capture(c);
  write_image(c.dir.path() / "distractor_masks/view_0.png", FloatImage{10, 12, 1, std::vector<float>(120, 1.0f)});
  std::ofstream(c.dir.path() / "distractor_masks/view_1.png") << "not a png";
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 2));
  const std::string wrong_size = error_of<SceneError>([&] { load_view_mask(scene, 0); });
  EXPECT_CONTAINS(wrong_size, "view_0.png");
  EXPECT_CONTAINS(wrong_size, "10x12");
  EXPECT_CONTAINS(wrong_size, "64x48");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_mask(scene, 1); }), "distractor_masks/view_1.png");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_mask(scene, 7); }), "does not exist");
}

// ---- User masks (pixels to ignore) --------------------------------------------------------------

// A black rectangle [x0, x0 + w) × [y0, y0 + h) on white, photo-sized; `grey_edge` puts 0.4 and
// 0.6 grey columns left and right of it (an editor's anti-aliasing: 0.4 → ignore, 0.6 → use).
FloatImage user_mask(int x0, int y0, int w, int h, bool grey_edge = false) {
  FloatImage m{kW, kH, 1, std::vector<float>(kW * kH, 1.0f)};
  for (int y = y0; y < y0 + h; ++y) {
    for (int x = x0; x < x0 + w; ++x) m.pixels[y * kW + x] = 0.0f;
    if (grey_edge) m.pixels[y * kW + x0 - 1] = 0.4f, m.pixels[y * kW + x0 + w] = 0.6f;
  }
  return m;
}

// The capture with a PINHOLE lens: training pixels are the photo's pixels (downscale 1) or
// their 2×2 blocks (downscale 2), so which pixels must be ignored can be counted by hand.
void use_pinhole_lens(MaskedCapture& c) {
  colmap::Model m = distorted_model();
  m.cameras[1] = colmap::Camera{1, CameraModelId::Pinhole, kW, kH, {50.0, 52.0, 32.0, 24.0}};
  colmap::write_model_binary(m, c.dir.path() / "sparse/0");
}

TEST(UserMasks, FoundByEitherNameConventionWithAWarningForPhotosWithout) {
  MaskedCapture c;
  write_masked_capture(c, false);
  write_image(c.dir.path() / "masks/view_0.png.png", user_mask(5, 5, 4, 4));  // COLMAP: <name>.png
  write_image(c.dir.path() / "masks/view_1.png", user_mask(5, 5, 4, 4));      // nerfstudio: <stem>.png
  std::vector<std::string> warnings;
  SceneOptions o = all_train(c.cache.path(), 1);
  o.on_warning = [&](const std::string& w) { warnings.push_back(w); };
  const Scene scene = load_colmap_scene(c.dir.path(), o);
  EXPECT_EQ(scene.masks_dir, scene.data_dir / "masks");
  EXPECT_EQ(scene.views[0].user_mask_path, scene.data_dir / "masks/view_0.png.png");
  EXPECT_EQ(scene.views[1].user_mask_path, scene.data_dir / "masks/view_1.png");
  EXPECT_TRUE(scene.views[2].user_mask_path.empty());
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_CONTAINS(warnings[0], "has no mask for 1 of 3 photos; every pixel of those is used");

  // --masks elsewhere; a folder that is not there, or holds no photo's mask, is an error.
  TempDir elsewhere{"user_masks"};
  write_image(elsewhere.path() / "view_2.png", user_mask(5, 5, 4, 4));
  o.masks_dir = elsewhere.path();
  const Scene other = load_colmap_scene(c.dir.path(), o);
  EXPECT_TRUE(other.views[0].user_mask_path.empty());
  EXPECT_EQ(other.views[2].user_mask_path, elsewhere.path() / "view_2.png");
  o.masks_dir = elsewhere.path() / "missing";
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_colmap_scene(c.dir.path(), o); }),
                  "the masks folder " + (elsewhere.path() / "missing").string() + " does not exist");
  fs::remove(elsewhere.path() / "view_2.png");
  write_image(elsewhere.path() / "unrelated.png", user_mask(5, 5, 4, 4));
  o.masks_dir = elsewhere.path();
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_colmap_scene(c.dir.path(), o); }), "holds no mask for any photo");

  // Without a masks/ folder nothing is masked.
  fs::remove_all(c.dir.path() / "masks");
  const Scene none = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  EXPECT_TRUE(none.masks_dir.empty());
  for (const SceneView& v : none.views) EXPECT_TRUE(v.user_mask_path.empty());
}

TEST(UserMasks, ATrainingPixelIsKeptOnlyWhenAllItCoversIsKept) {
  MaskedCapture c;
  write_masked_capture(c, false);
  use_pinhole_lens(c);
  write_image(c.dir.path() / "masks/view_0.png.png", user_mask(9, 7, 5, 6, /*grey_edge=*/true));
  for (int downscale : {1, 2}) {
    const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), downscale));
    const std::vector<float> keep = load_view_keep_mask(scene, 0);
    const int w = kW / downscale, h = kH / downscale;
    ASSERT_EQ(keep.size(), size_t(w) * h);
    // Photo pixels ignored: x in [8, 14) (the black columns plus the 0.4 grey one left of
    // them; the 0.6 one right of them is used), y in [7, 13). A training pixel is ignored when
    // its block touches one.
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        bool touches = false;
        for (int dy = 0; dy < downscale; ++dy)
          for (int dx = 0; dx < downscale; ++dx) {
            const int px = x * downscale + dx, py = y * downscale + dy;
            touches |= px >= 8 && px < 14 && py >= 7 && py < 13;
          }
        EXPECT_EQ(keep[size_t(y) * w + x], touches ? 0.0f : 1.0f) << x << "," << y << " downscale " << downscale;
      }
  }
}

TEST(UserMasks, AMaskOfTheWrongSizeOrUnreadableNamesTheFile) {
  MaskedCapture c;
  write_masked_capture(c, false);
  write_image(c.dir.path() / "masks/view_0.png", FloatImage{10, 12, 1, std::vector<float>(120, 1.0f)});
  std::ofstream(c.dir.path() / "masks/view_1.png.png") << "not a png";
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  const std::string wrong_size = error_of<SceneError>([&] { load_view_keep_mask(scene, 0); });
  EXPECT_CONTAINS(wrong_size, (scene.data_dir / "masks/view_0.png").string() +
                                  ": mask is 10x12 px but the photo 'view_0.png' is 64x48 px");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_keep_mask(scene, 1); }),
                  "masks/view_1.png.png: cannot read the mask");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_keep_mask(scene, 2); }), "has no mask of pixels to ignore");
  // Training reports one of them (views load in parallel) before its first step.
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_training_data(scene); }), (scene.data_dir / "masks/view_").string());
}

// What training is handed: the mask, and zeros where it ignores (the photo there is never read).
TEST(UserMasks, TrainingDataCarriesTheMaskAndZeroesIgnoredPixels) {
  MaskedCapture c;
  write_masked_capture(c, false);
  use_pinhole_lens(c);
  write_image(c.dir.path() / "masks/view_1.png", user_mask(20, 10, 6, 4));
  const Scene scene = load_colmap_scene(c.dir.path(), all_train(c.cache.path(), 1));
  const TrainingData data = load_training_data(scene);
  ASSERT_EQ(data.train.size(), 3u);
  EXPECT_TRUE(data.train[0].keep.empty());
  const TrainView& v = data.train[1];
  ASSERT_EQ(v.keep.size(), size_t(kW * kH));
  int ignored = 0;
  for (int p = 0; p < kW * kH; ++p) {
    const bool inside = p % kW >= 20 && p % kW < 26 && p / kW >= 10 && p / kW < 14;
    EXPECT_EQ(v.keep[p], inside ? 0 : 1) << p;
    if (inside) {
      ++ignored;
      EXPECT_EQ(v.image.pixels[3 * p] + v.image.pixels[3 * p + 1] + v.image.pixels[3 * p + 2], 0) << p;
    } else {
      EXPECT_NEAR(byte_to_float(v.image.pixels[3 * p]), c.patterns[1].pixels[p], 1e-6f) << p;
    }
  }
  EXPECT_EQ(ignored, 24);
}

}  // namespace
