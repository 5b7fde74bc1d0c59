// Distractor masks (masks.hpp): scoring against hand-counted cases, mask discovery and
// loading through the same resize + undistortion as the photos (on a small capture with a
// strongly distorted OPENCV lens written here), and desplat_occlude's library job
// (occluders.hpp) on the real fox capture (read-only input).
//
// Independent expectations: hand-counted IoUs; an image whose pixel values equal its mask's,
// which must come out of load_view_image with the same values as load_view_mask; keypoint
// mapping (undistort_pixel) for where a mask blob lands; the input files' own bytes and
// decoded pixels; the colours, boxes and source patches listed in occluders.json.
#include <gtest/gtest.h>
#include <unistd.h>

#include <OpenImageIO/imageio.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "desplat/io/colmap.hpp"
#include "desplat/io/masks.hpp"
#include "desplat/synth/occluders.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/io/undistort.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using colmap::CameraModelId;

namespace {

const fs::path kFox = "/work/shared/data/fox";

struct TempDir {
  fs::path path;
  explicit TempDir(const std::string& tag) {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("desplat_test_masks_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

template <class Error, class Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("wrong exception type: ") + e.what();
  }
  return "no exception";
}

#define EXPECT_CONTAINS(haystack, needle) EXPECT_NE((haystack).find(needle), std::string::npos) << (haystack)

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

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
    const Eigen::Vector3d f = -C.normalized();
    const Eigen::Vector3d r = Eigen::Vector3d(0, 1, 0).cross(f).normalized();
    Eigen::Matrix3d R;
    R.row(0) = r;
    R.row(1) = f.cross(r);
    R.row(2) = f;
    const Eigen::Quaterniond q(R);
    const Eigen::Vector3d t = -R * C;
    colmap::Image im;
    im.id = uint32_t(i + 1);
    im.qvec_wxyz = {q.w(), q.x(), q.y(), q.z()};
    im.tvec = {t.x(), t.y(), t.z()};
    im.camera_id = 1;
    im.name = "view_" + std::to_string(i) + ".png";
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
  TempDir dir{"capture"};
  TempDir cache{"cache"};
  std::vector<FloatImage> patterns;
};

// Every view's photo is RGB = its mask's grey values; view 2 has no mask file, view 1's is 16-bit.
void write_masked_capture(MaskedCapture& c, bool with_masks = true) {
  const colmap::Model m = distorted_model();
  colmap::write_model_binary(m, c.dir.path / "sparse/0");
  for (const auto& [id, im] : m.images) {
    c.patterns.push_back(grey_pattern(int(id)));
    write_image(c.dir.path / "images" / im.name, as_rgb(c.patterns.back()));
  }
  if (!with_masks) return;
  write_image(c.dir.path / "distractor_masks/view_0.png", c.patterns[0]);
  write_mask_16bit_two_channels(c.dir.path / "distractor_masks/view_1.png", c.patterns[1]);
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
  const Scene scene = load_colmap_scene(c.dir.path, all_train(c.cache.path, 1));
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
  const Scene scene = load_colmap_scene(c.dir.path, all_train(c.cache.path, 1));
  for (const SceneView& v : scene.views) EXPECT_TRUE(v.mask_path.empty()) << v.name;
}

// The photo (8-bit PNG, through the PNG cache) and the mask (float, not cached) go through
// the same INTER_AREA resize and bilinear remap, per channel, in float. The only difference is
// the cache's 8-bit rounding of the photo, ≤ 0.5/255; 1e-5 covers float summation order.
TEST(LoadViewMask, MatchesThePhotoPixelForPixel) {
  MaskedCapture c;
  write_masked_capture(c);
  for (int downscale : {1, 2}) {
    const Scene scene = load_colmap_scene(c.dir.path, all_train(c.cache.path, downscale));
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
      for (size_t p = 0; p < mask.pixels.size(); ++p) worst = std::max(worst, std::abs(mask.pixels[p] - photo.pixels[3 * p]));
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
  write_image(c.dir.path / "distractor_masks/view_0.png", blob);
  const Scene scene = load_colmap_scene(c.dir.path, all_train(c.cache.path, 1));
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
  write_image(c.dir.path / "distractor_masks/view_0.png", FloatImage{10, 12, 1, std::vector<float>(120, 1.0f)});
  std::ofstream(c.dir.path / "distractor_masks/view_1.png") << "not a png";
  const Scene scene = load_colmap_scene(c.dir.path, all_train(c.cache.path, 2));
  const std::string wrong_size = error_of<SceneError>([&] { load_view_mask(scene, 0); });
  EXPECT_CONTAINS(wrong_size, "view_0.png");
  EXPECT_CONTAINS(wrong_size, "10x12");
  EXPECT_CONTAINS(wrong_size, "64x48");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_mask(scene, 1); }), "distractor_masks/view_1.png");
  EXPECT_CONTAINS(error_of<SceneError>([&] { load_view_mask(scene, 7); }), "does not exist");
}

// ---- occlude_scene on fox --------------------------------------------------------------------------

struct Decoded {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  // [H, W, C]
  float at(int x, int y, int c) const { return pixels[(size_t(y) * width + x) * channels + c]; }
};

Decoded decode(const fs::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  EXPECT_TRUE(in) << path;
  if (!in) return {};
  const OIIO::ImageSpec& s = in->spec();
  Decoded d{s.width, s.height, s.nchannels, std::vector<float>(size_t(s.width) * s.height * s.nchannels)};
  EXPECT_TRUE(in->read_image(0, 0, 0, s.nchannels, OIIO::TypeDesc::FLOAT, d.pixels.data())) << path;
  return d;
}

// Fox's roles, worked out here: every 8th image by name is a test view.
std::map<std::string, bool> fox_is_test() {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(kFox / "images")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  std::map<std::string, bool> roles;
  for (size_t i = 0; i < names.size(); ++i) roles[names[i]] = i % 8 == 0;
  return roles;
}

constexpr double kFraction = 0.2;

OccludeOptions fox_options(const fs::path& out, uint64_t seed = 3) {
  OccludeOptions o;
  o.data_dir = kFox;
  o.out_dir = out;
  o.fraction = kFraction;
  o.seed = seed;
  return o;
}

// One run shared by the fox tests (the job takes about a second).
class OccludeFox : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir("fox");
    report_ = new OccludeReport(occlude_scene(fox_options(dir_->path / "out")));
  }
  static void TearDownTestSuite() {
    delete report_;
    delete dir_;
  }
  static fs::path out() { return dir_->path / "out"; }
  static inline TempDir* dir_ = nullptr;
  static inline OccludeReport* report_ = nullptr;
};

TEST_F(OccludeFox, CopiesTheModelAndUntouchedViewsByteForByte) {
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    EXPECT_EQ(slurp(out() / "sparse/0" / f), slurp(kFox / "sparse/0" / f)) << f;
  const auto is_test = fox_is_test();
  ASSERT_EQ(report_->views.size(), is_test.size());
  size_t train = 0, occluded = 0;
  for (const OccludedView& v : report_->views) {
    ASSERT_TRUE(is_test.count(v.name)) << v.name;
    EXPECT_EQ(v.role, is_test.at(v.name) ? ViewRole::Test : ViewRole::Train) << v.name;
    train += v.role == ViewRole::Train;
    occluded += v.occluded;
    EXPECT_TRUE(!v.occluded || v.role == ViewRole::Train) << v.name;
    const bool same = slurp(out() / "images" / v.name) == slurp(kFox / "images" / v.name);
    EXPECT_EQ(same, !v.occluded) << v.name;
  }
  EXPECT_EQ(occluded, size_t(std::lround(kFraction * double(train))));
}

TEST_F(OccludeFox, EveryTrainingViewHasAMaskCoveringTheReportedArea) {
  for (const OccludedView& v : report_->views) {
    const fs::path mask_file = out() / "distractor_masks" / fs::path(v.name).replace_extension(".png");
    if (v.role != ViewRole::Train) {
      EXPECT_FALSE(fs::exists(mask_file)) << v.name;
      continue;
    }
    ASSERT_TRUE(fs::exists(mask_file)) << v.name;
    const Decoded m = decode(mask_file);
    ASSERT_EQ(m.channels, 1);
    size_t covered = 0, outside_boxes = 0;
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x) {
        const float value = m.at(x, y, 0);
        ASSERT_TRUE(value == 0.0f || value == 1.0f) << v.name;  // 0 or 255, nothing in between
        if (value == 0.0f) continue;
        ++covered;
        bool in_a_box = false;
        for (const Occluder& o : v.occluders) in_a_box |= x >= o.box[0] && x < o.box[2] && y >= o.box[1] && y < o.box[3];
        outside_boxes += !in_a_box;
      }
    EXPECT_EQ(outside_boxes, 0u) << v.name;
    EXPECT_DOUBLE_EQ(double(covered) / (double(m.width) * m.height), v.covered_fraction) << v.name;
    if (!v.occluded) {
      EXPECT_EQ(covered, 0u) << v.name;
      continue;
    }
    EXPECT_GE(v.covered_fraction, 0.05) << v.name;  // the default coverage range
    EXPECT_LE(v.covered_fraction, 0.25) << v.name;
    EXPECT_GE(v.occluders.size(), 1u);
    EXPECT_LE(v.occluders.size(), 3u);
  }
}

// JPEG at quality 95, 4:4:4, codes each aligned 8×8 block on its own: a block without a mask
// pixel changes only by re-encoding noise. Measured on fox (largest channel |Δ| per pixel):
// mean 1.1–1.3/255, 99.9th percentile 5–6/255, maximum 12/255; the bounds (2/255, 10/255)
// leave headroom for other libjpeg builds yet fail for any real edit. Inside the mask a pasted
// occluder differs from the scene behind it far above that noise (measured: 94–100 % of the
// covered pixels by more than 24/255).
TEST_F(OccludeFox, PixelsChangeInsideTheMaskAndOnlyByJpegNoiseOutside) {
  for (const OccludedView& v : report_->views) {
    if (!v.occluded) continue;
    const Decoded before = decode(kFox / "images" / v.name), after = decode(out() / "images" / v.name);
    const Decoded m = decode(out() / "distractor_masks" / fs::path(v.name).replace_extension(".png"));
    ASSERT_EQ(before.width, after.width);
    ASSERT_EQ(before.height, after.height);
    ASSERT_EQ(after.channels, 3);
    std::vector<uint8_t> block_touched(size_t((m.width + 7) / 8) * ((m.height + 7) / 8), 0);
    const auto block = [&](int x, int y) -> uint8_t& { return block_touched[size_t(y / 8) * ((m.width + 7) / 8) + x / 8]; };
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x)
        if (m.at(x, y, 0) > 0.5f) block(x, y) = 1;
    std::vector<float> outside;
    size_t inside = 0, inside_changed = 0;
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x) {
        float diff = 0;
        for (int ch = 0; ch < 3; ++ch) diff = std::max(diff, std::abs(after.at(x, y, ch) - before.at(x, y, ch)));
        if (m.at(x, y, 0) > 0.5f) {
          ++inside;
          inside_changed += diff > 24.0f / 255;  // 4× the outside noise bound
        } else if (!block(x, y)) {
          outside.push_back(diff);
        }
      }
    ASSERT_FALSE(outside.empty());
    double mean = 0;
    for (float d : outside) mean += d;
    mean /= double(outside.size());
    std::sort(outside.begin(), outside.end());
    EXPECT_LT(mean, 2.0 / 255) << v.name;
    EXPECT_LE(outside[size_t(0.999 * double(outside.size() - 1))], 10.0f / 255) << v.name;
    // Flat colours, or another part of the scene: most covered pixels change visibly.
    EXPECT_GT(double(inside_changed) / double(inside), 0.5) << v.name;
  }
}

// Each view's topmost occluder shows what occluders.json says: its colour, or the source
// photo's pixels at source_box. Checked on pixels whose 8×8 JPEG block lies wholly inside
// the occluder (rectangles: the box; ellipses: the ellipse inscribed in the box, shrunk by
// a block's diagonal), where only re-encoding noise separates them (measured mean |Δ|:
// 0–0.35/255 for flat colours, 0.9/255 for patches; bound as for the noise outside).
TEST_F(OccludeFox, TopmostOccluderShowsTheReportedContent) {
  int checked = 0;
  std::set<std::string> kinds;
  for (const OccludedView& v : report_->views) {
    for (const Occluder& o : v.occluders) kinds.insert(o.kind);
    if (!v.occluded || v.occluders.back().kind == "polygon") continue;
    const Occluder& o = v.occluders.back();
    const Decoded after = decode(out() / "images" / v.name);
    Decoded source;
    if (!o.source_image.empty()) {
      EXPECT_NE(o.source_image, v.name);
      source = decode(kFox / "images" / o.source_image);
      const bool disjoint = o.source_box[2] <= o.box[0] || o.box[2] <= o.source_box[0] || o.source_box[3] <= o.box[1] ||
                            o.box[3] <= o.source_box[1];
      EXPECT_TRUE(disjoint) << v.name;
      EXPECT_EQ(o.source_box[2] - o.source_box[0], o.box[2] - o.box[0]);
      EXPECT_EQ(o.source_box[3] - o.source_box[1], o.box[3] - o.box[1]);
    }
    const bool elliptic = o.kind.find("ellipse") != std::string::npos;
    const double cx = (o.box[0] + o.box[2]) / 2.0, cy = (o.box[1] + o.box[3]) / 2.0;
    const double ax = (o.box[2] - o.box[0]) / 2.0 - 12, ay = (o.box[3] - o.box[1]) / 2.0 - 12;
    const auto deep_inside = [&](double x, double y) {
      if (!elliptic) return x >= o.box[0] && x <= o.box[2] && y >= o.box[1] && y <= o.box[3];
      return ax > 0 && ay > 0 && std::pow((x - cx) / ax, 2) + std::pow((y - cy) / ay, 2) <= 1;
    };
    double sum = 0;
    size_t n = 0;
    for (int by = 0; by + 8 <= after.height; by += 8)
      for (int bx = 0; bx + 8 <= after.width; bx += 8) {
        if (!deep_inside(bx, by) || !deep_inside(bx + 8, by) || !deep_inside(bx, by + 8) || !deep_inside(bx + 8, by + 8))
          continue;
        for (int y = by; y < by + 8; ++y)
          for (int x = bx; x < bx + 8; ++x)
            for (int ch = 0; ch < 3; ++ch) {
              const float expected = o.source_image.empty()
                                         ? o.color[ch] / 255.0f
                                         : source.at(x + o.source_box[0] - o.box[0], y + o.source_box[1] - o.box[1], ch);
              sum += std::abs(after.at(x, y, ch) - expected);
              ++n;
            }
      }
    if (n == 0) continue;  // too small for a whole block
    ++checked;
    EXPECT_LT(sum / double(n), 2.0 / 255) << v.name << " " << o.kind;
  }
  EXPECT_GE(checked, 3);
  EXPECT_GE(kinds.size(), 3u) << "the occluders should mix shapes and patches";
}

TEST_F(OccludeFox, ReportFileListsEveryView) {
  const nlohmann::json j = nlohmann::json::parse(slurp(out() / "occluders.json"));
  ASSERT_EQ(j["views"].size(), report_->views.size());
  for (size_t i = 0; i < report_->views.size(); ++i) {
    const OccludedView& v = report_->views[i];
    const nlohmann::json& jv = j["views"][i];
    EXPECT_EQ(jv["name"], v.name);
    if (v.role != ViewRole::Train) continue;
    EXPECT_EQ(jv["occluded"], v.occluded);
    EXPECT_DOUBLE_EQ(jv["covered_fraction"].get<double>(), v.covered_fraction);
    ASSERT_EQ(jv["occluders"].size(), v.occluders.size());
    for (size_t k = 0; k < v.occluders.size(); ++k) {
      EXPECT_EQ(jv["occluders"][k]["kind"], v.occluders[k].kind);
      EXPECT_EQ(jv["occluders"][k]["box"].get<std::vector<int>>(),
                std::vector<int>(v.occluders[k].box.begin(), v.occluders[k].box.end()));
    }
  }
}

// The output is a scene: it loads, and at downscale 2 through fox's distorted lens the
// mask still marks exactly where the occluded photo differs from the original one.
TEST_F(OccludeFox, OutputLoadsAndMasksLineUpWithTheChangedPixels) {
  TempDir cache("fox_cache");
  SceneOptions o;
  o.downscale = 2;
  o.cache_dir = cache.path;
  const Scene occluded = load_colmap_scene(out(), o);
  const Scene original = load_colmap_scene(kFox, o);
  ASSERT_EQ(occluded.views.size(), original.views.size());
  size_t view = occluded.views.size();
  for (size_t i = 0; i < occluded.views.size(); ++i) {
    EXPECT_EQ(occluded.views[i].mask_path.empty(), occluded.views[i].is_test) << occluded.views[i].name;
    const auto& r = report_->views[i];
    if (r.occluded && view == occluded.views.size()) view = i;
  }
  ASSERT_LT(view, occluded.views.size());
  const FloatImage a = load_view_image(occluded, view), b = load_view_image(original, view);
  const FloatImage m = load_view_mask(occluded, view);
  ASSERT_EQ(m.width * m.height * 3, int(a.pixels.size()));
  double changed_in = 0, changed_out = 0, n_in = 0, n_out = 0;
  for (size_t p = 0; p < m.pixels.size(); ++p) {
    float diff = 0;
    for (int c = 0; c < 3; ++c) diff = std::max(diff, std::abs(a.pixels[3 * p + c] - b.pixels[3 * p + c]));
    if (m.pixels[p] > 0.5f) n_in += 1, changed_in += diff > 24.0f / 255;
    else if (m.pixels[p] == 0.0f) n_out += 1, changed_out += diff > 24.0f / 255;
  }
  ASSERT_GT(n_in, 0);
  EXPECT_GT(changed_in / n_in, 0.5);
  EXPECT_LT(changed_out / n_out, 0.01);  // measured 0: only JPEG noise outside, far below 24/255
}

TEST(OccludeScene, SameSeedSameFilesOtherSeedOtherOccluders) {
  TempDir dir("determinism");
  occlude_scene(fox_options(dir.path / "a", 11));
  occlude_scene(fox_options(dir.path / "b", 11));
  occlude_scene(fox_options(dir.path / "c", 12));
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir.path / "a")) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = e.path().lexically_relative(dir.path / "a");
    EXPECT_EQ(slurp(e.path()), slurp(dir.path / "b" / rel)) << rel;
    ++files;
  }
  EXPECT_EQ(files, 3 + 50 + 43 + 1u);  // model, images, training masks, occluders.json
  EXPECT_NE(slurp(dir.path / "a/occluders.json"), slurp(dir.path / "c/occluders.json"));
}

// Tracks: the training views, in name order, cut into runs of 4; a run is occluded whole or
// not at all, round(0.5 · 43 / 4) = 5 runs are, and every view of a run carries the same
// occluders and the same mask, with patches cut only from photos outside the run.
TEST(OccludeScene, TracksShareOccludersOverConsecutiveTrainingViews) {
  TempDir dir("tracks");
  OccludeOptions o = fox_options(dir.path / "out");
  o.fraction = 0.5;
  o.track_length = 4;
  const OccludeReport report = occlude_scene(o);
  std::vector<const OccludedView*> train;
  for (const OccludedView& v : report.views)
    if (!fox_is_test().at(v.name)) train.push_back(&v);
  ASSERT_EQ(train.size(), 43u);
  int occluded_runs = 0;
  for (size_t first = 0; first < train.size(); first += 4) {
    const size_t end = std::min(first + 4, train.size());
    const OccludedView& a = *train[first];
    occluded_runs += a.occluded;
    const std::string mask_a = slurp(distractor_mask_path(o.out_dir, a.name));
    std::set<std::string> run_names;
    for (size_t i = first; i < end; ++i) run_names.insert(train[i]->name);
    for (size_t i = first; i < end; ++i) {
      const OccludedView& b = *train[i];
      ASSERT_EQ(b.occluded, a.occluded) << b.name;
      EXPECT_EQ(slurp(distractor_mask_path(o.out_dir, b.name)), mask_a) << b.name;
      ASSERT_EQ(b.occluders.size(), a.occluders.size()) << b.name;
      for (size_t k = 0; k < b.occluders.size(); ++k) {
        EXPECT_EQ(b.occluders[k].kind, a.occluders[k].kind);
        EXPECT_EQ(b.occluders[k].box, a.occluders[k].box);
        EXPECT_EQ(b.occluders[k].color, a.occluders[k].color);
        EXPECT_EQ(b.occluders[k].source_image, a.occluders[k].source_image);
        EXPECT_EQ(run_names.count(b.occluders[k].source_image), 0u) << b.name << " pastes from its own run";
      }
      if (b.occluded) {
        EXPECT_GT(b.covered_fraction, 0.0);
      }
    }
  }
  EXPECT_EQ(occluded_runs, 5);

  // Runs of one are the independent views of the default.
  OccludeOptions one = fox_options(dir.path / "one");
  one.track_length = 1;
  OccludeOptions def = fox_options(dir.path / "default");
  const OccludeReport r1 = occlude_scene(one), r0 = occlude_scene(def);
  for (size_t i = 0; i < r0.views.size(); ++i) {
    EXPECT_EQ(r1.views[i].occluded, r0.views[i].occluded);
    EXPECT_EQ(slurp(dir.path / "one/images" / r1.views[i].name), slurp(dir.path / "default/images" / r0.views[i].name));
  }
}

TEST(OccludeScene, BadInputGivesOneClearError) {
  TempDir dir("errors");
  const auto error = [](const OccludeOptions& o) { return error_of<OccludeError>([&] { occlude_scene(o); }); };
  OccludeOptions o = fox_options(dir.path / "out");
  o.fraction = 1.5;
  EXPECT_CONTAINS(error(o), "--fraction");
  o = fox_options(dir.path / "out");
  o.coverage_min = 0.3;
  o.coverage_max = 0.2;
  EXPECT_CONTAINS(error(o), "--coverage-min");
  o = fox_options(dir.path / "out");
  o.track_length = 0;
  EXPECT_CONTAINS(error(o), "--track");
  o = fox_options(kFox / "occluded");
  EXPECT_CONTAINS(error(o), "must not be the input folder");
  o = fox_options(kFox);
  EXPECT_CONTAINS(error(o), "must not be the input folder");
  o = fox_options(dir.path / "out");
  o.data_dir = dir.path / "nowhere";
  EXPECT_CONTAINS(error(o), "nowhere");
  EXPECT_FALSE(fs::exists(dir.path / "out" / "images"));  // nothing written on bad input

  // A capture with a registered image that has no file.
  const fs::path broken = dir.path / "broken";
  fs::create_directories(broken / "images");
  fs::copy(kFox / "sparse", broken / "sparse", fs::copy_options::recursive);
  o = fox_options(dir.path / "out2");
  o.data_dir = broken;
  const std::string missing = error(o);
  EXPECT_CONTAINS(missing, (broken / "images").string());
  EXPECT_CONTAINS(missing, "no file for registered image");

  // A second run into the same folder needs --overwrite.
  o = fox_options(dir.path / "out3");
  o.fraction = 0;
  occlude_scene(o);
  EXPECT_CONTAINS(error(o), "--overwrite");
  o.overwrite = true;
  EXPECT_EQ(occlude_scene(o).views.size(), 50u);
}

}  // namespace
