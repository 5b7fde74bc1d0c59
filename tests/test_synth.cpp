// The synthetic scene generator (synth.hpp) on the tiny checked-in descriptions.
//
// Independent expectations: the COLMAP model is read back by our reader, by load_colmap_scene
// and by the real `colmap model_analyzer`; projections are recomputed here from the raw
// quaternions with the pinhole and OPENCV formulas written out in this file (not through
// camera_models.hpp); the cluttered views follow the documented even spread, recomputed here;
// files are compared byte for byte.
#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numbers>
#include <regex>
#include <set>
#include <sstream>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/synth/synth.hpp"
#include "support/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using json = nlohmann::json;

namespace {
using desplat::testing::TempDir;

const fs::path kDescriptions = fs::path(DESPLAT_SOURCE_DIR) / "data" / "synthetic";

synth::Description tiny(const std::string& name, const json& patch = json::object()) {
  const synth::Description d = synth::load_description(kDescriptions / name);
  return patch.empty() ? d : synth::apply_description(d, patch, "test");
}

synth::GenerationReport generate(const synth::Description& d, const fs::path& out) {
  synth::GenerateOptions o;
  o.out = out;
  return synth::generate_scene(d, o);
}

std::string bytes_of(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::vector<std::string> lines_of(const fs::path& p) {
  std::ifstream f(p);
  std::vector<std::string> out;
  for (std::string line; std::getline(f, line);) out.push_back(line);
  return out;
}

// Every file under `dir` (relative path -> bytes).
std::map<std::string, std::string> tree(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = bytes_of(e.path());
  return files;
}

template <class Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const synth::SynthError& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("wrong exception type: ") + e.what();
  }
  return "no exception";
}

// Camera-space point of a world point, from the stored quaternion (w, x, y, z) and translation.
std::array<double, 3> to_camera(const colmap::Image& im, const std::array<double, 3>& p) {
  const double n = std::sqrt(im.qvec_wxyz[0] * im.qvec_wxyz[0] + im.qvec_wxyz[1] * im.qvec_wxyz[1] +
                             im.qvec_wxyz[2] * im.qvec_wxyz[2] + im.qvec_wxyz[3] * im.qvec_wxyz[3]);
  const double w = im.qvec_wxyz[0] / n, x = im.qvec_wxyz[1] / n, y = im.qvec_wxyz[2] / n, z = im.qvec_wxyz[3] / n;
  const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  std::array<double, 3> q{};
  for (int r = 0; r < 3; ++r) q[r] = R[r][0] * p[0] + R[r][1] * p[1] + R[r][2] * p[2] + im.tvec[r];
  return q;
}

// Pixel of a camera-space point: PINHOLE, or OPENCV's radial-tangential distortion.
std::array<double, 2> to_pixel(const colmap::Camera& cam, const std::array<double, 3>& q, bool with_distortion = true) {
  double u = q[0] / q[2], v = q[1] / q[2];
  const auto& k = cam.params;
  if (cam.model == colmap::CameraModelId::OpenCV && with_distortion) {
    const double r2 = u * u + v * v, radial = 1 + k[4] * r2 + k[5] * r2 * r2;
    const double du = 2 * k[6] * u * v + k[7] * (r2 + 2 * u * u), dv = k[6] * (r2 + 2 * v * v) + 2 * k[7] * u * v;
    u = u * radial + du;
    v = v * radial + dv;
  }
  return {k[0] * u + k[2], k[1] * v + k[3]};
}

// Largest and mean distance between each point's projection and its stored observations.
struct Residuals {
  double max = 0, mean = 0;
  size_t count = 0;
};
Residuals residuals(const colmap::Model& m) {
  Residuals r;
  double sum = 0;
  for (const auto& [id, p] : m.points)
    for (const auto& t : p.track) {
      const colmap::Image& im = m.images.at(t.image_id);
      const auto& obs = im.points2d.at(t.point2d_idx);
      EXPECT_EQ(obs.point3d_id, static_cast<int64_t>(id));
      const auto px = to_pixel(m.cameras.at(im.camera_id), to_camera(im, p.xyz));
      const double d = std::hypot(px[0] - obs.x, px[1] - obs.y);
      r.max = std::max(r.max, d);
      sum += d;
      ++r.count;
    }
  r.mean = r.count ? sum / static_cast<double>(r.count) : 0;
  return r;
}

// The training views the generator documents as cluttered: round(ratio·n) spread evenly.
std::set<std::string> expected_cluttered(int count, double ratio) {
  std::vector<std::string> train;
  for (int k = 0; k < count; ++k)
    if (k % 8 != 0) train.push_back(synth::view_name(k, count));
  const long n = static_cast<long>(train.size()), m = std::lround(ratio * static_cast<double>(n));
  std::set<std::string> out;
  for (long j = 0; j < n; ++j)
    if ((j + 1) * m / n > j * m / n) out.insert(train[static_cast<size_t>(j)]);
  return out;
}

bool any_nonzero(const FloatImage& im) {
  return std::any_of(im.pixels.begin(), im.pixels.end(), [](float v) { return v > 0; });
}

}  // namespace

TEST(Synth, TinyCleanLoadsWithOurReaderAndTheSceneLoader) {
  TempDir t;
  const auto d = tiny("tiny_clean.json");
  ASSERT_EQ(d.camera.width, 64);
  ASSERT_EQ(d.camera.height, 48);
  ASSERT_EQ(d.views.count, 8);
  const auto report = generate(d, t.path() / "scene");

  const colmap::Model m = colmap::read_model(t.path() / "scene" / "sparse" / "0");
  ASSERT_EQ(m.cameras.size(), 1u);
  EXPECT_EQ(m.cameras.begin()->second.width, 64u);
  EXPECT_EQ(m.cameras.begin()->second.height, 48u);
  ASSERT_EQ(m.images.size(), 8u);
  std::vector<std::string> names;
  for (const auto& [id, im] : m.images) names.push_back(im.name);
  EXPECT_EQ(names, (std::vector<std::string>{"0000.png", "0001.png", "0002.png", "0003.png", "0004.png", "0005.png",
                                             "0006.png", "0007.png"}));
  EXPECT_GT(m.points.size(), 100u);
  EXPECT_EQ(m.points.size(), report.num_points);
  for (const auto& [id, p] : m.points) EXPECT_GE(p.track.size(), 2u) << "point " << id;

  SceneOptions o;
  o.cache_dir = t.path() / "cache";
  o.on_warning = [](const std::string& w) { ADD_FAILURE() << w; };
  const Scene scene = load_colmap_scene(t.path() / "scene", o);
  ASSERT_EQ(scene.views.size(), 8u);
  ASSERT_EQ(scene.test_views().size(), 1u);
  EXPECT_EQ(scene.views[scene.test_views()[0]].name, "0000.png");
  EXPECT_EQ(scene.points_xyz.size(), m.points.size());
  EXPECT_EQ(lines_of(t.path() / "scene" / "test_list.txt"), std::vector<std::string>{"0000.png"});
  EXPECT_EQ(lines_of(t.path() / "scene" / "train_list.txt").size(), 7u);
  const FloatImage img = load_view_image(scene, 3);
  EXPECT_EQ(img.width, 64);
  EXPECT_EQ(img.height, 48);
  // scene.json is the effective description and reads back as the same description.
  EXPECT_EQ(synth::load_description(t.path() / "scene" / "scene.json"), d);
}

TEST(Synth, ColmapModelAnalyzerAcceptsTheModel) {
  if (std::system("command -v colmap > /dev/null 2>&1") != 0) GTEST_SKIP() << "colmap is not on PATH";
  TempDir t;
  generate(tiny("tiny_distractors.json"), t.path() / "scene");
  const colmap::Model m = colmap::read_model(t.path() / "scene" / "sparse" / "0");
  const fs::path log = t.path() / "analyzer.log";
  const std::string cmd = "colmap model_analyzer --path '" + (t.path() / "scene" / "sparse" / "0").string() + "' > '" +
                          log.string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << bytes_of(log);
  const std::string text = bytes_of(log);
  std::smatch images, points;
  ASSERT_TRUE(std::regex_search(text, images, std::regex(R"(Registered images: (\d+))"))) << text;
  ASSERT_TRUE(std::regex_search(text, points, std::regex(R"(Points: (\d+))"))) << text;
  EXPECT_EQ(std::stoul(images[1]), 16u);
  EXPECT_EQ(std::stoul(points[1]), m.points.size());
}

TEST(Synth, PointsProjectExactlyOntoTheirObservationsWithoutNoise) {
  TempDir t;
  generate(tiny("tiny_clean.json", {{"points.position_noise_px", 0}, {"points.observation_noise_px", 0}}),
           t.path() / "s");
  const Residuals r = residuals(colmap::read_model(t.path() / "s" / "sparse" / "0"));
  ASSERT_GT(r.count, 500u);
  EXPECT_LT(r.max, 1e-6);
}

TEST(Synth, PointNoiseHasTheDescribedSize) {
  TempDir t;
  const auto d = tiny("tiny_clean.json", {{"points.count", 1500}});
  generate(d, t.path() / "s");
  const Residuals r = residuals(colmap::read_model(t.path() / "s" / "sparse" / "0"));
  // Per axis the reprojected error is N(0, σp² + σo²); its 2D length has mean σ·sqrt(π/2).
  const double sigma = std::hypot(d.points.position_noise_px, d.points.observation_noise_px);
  ASSERT_GT(sigma, 0.2);
  EXPECT_NEAR(r.mean, sigma * std::sqrt(std::numbers::pi / 2), 0.25 * sigma);
  EXPECT_LT(r.max, 8 * sigma);
}

TEST(Synth, DistortedForwardFacingCameraProjectsAndRendersThroughItsLens) {
  TempDir t;
  const auto d = tiny("tiny_clean.json", {{"camera.model", "OPENCV"},
                                          {"camera.distortion", {-0.3, 0.05, 0.002, -0.003}},
                                          {"views.path", "forward"},
                                          {"supersampling", 1},
                                          {"points.position_noise_px", 0},
                                          {"points.observation_noise_px", 0}});
  generate(d, t.path() / "s");
  const colmap::Model m = colmap::read_model(t.path() / "s" / "sparse" / "0");
  ASSERT_EQ(m.cameras.at(1).model, colmap::CameraModelId::OpenCV);
  const Residuals r = residuals(m);
  ASSERT_GT(r.count, 500u);
  EXPECT_LT(r.max, 1e-6);

  // The clean image shows a point's color where the lens puts the point, not where a pinhole
  // would: compare both places over all observations far enough from the centre to tell.
  double err_lens = 0, err_pinhole = 0;
  int n = 0;
  std::map<uint32_t, FloatImage> clean;
  for (const auto& [id, im] : m.images) clean[id] = read_image_rgb(t.path() / "s" / "clean" / im.name);
  for (const auto& [id, p] : m.points)
    for (const auto& tr : p.track) {
      const colmap::Image& im = m.images.at(tr.image_id);
      const auto q = to_camera(im, p.xyz);
      const auto lens = to_pixel(m.cameras.at(1), q), pin = to_pixel(m.cameras.at(1), q, false);
      if (std::hypot(lens[0] - pin[0], lens[1] - pin[1]) < 2 || pin[0] < 0 || pin[1] < 0 || pin[0] >= 64 ||
          pin[1] >= 48)
        continue;
      const auto value = [&](const std::array<double, 2>& px, int c) {
        const size_t i = (static_cast<size_t>(px[1]) * 64 + static_cast<size_t>(px[0])) * 3 + static_cast<size_t>(c);
        return clean[tr.image_id].pixels[i];
      };
      for (int c = 0; c < 3; ++c) {
        err_lens += std::abs(value(lens, c) - p.rgb[static_cast<size_t>(c)] / 255.0);
        err_pinhole += std::abs(value(pin, c) - p.rgb[static_cast<size_t>(c)] / 255.0);
      }
      ++n;
    }
  ASSERT_GT(n, 100);
  EXPECT_LT(err_lens, 0.6 * err_pinhole) << "lens " << err_lens / n << " pinhole " << err_pinhole / n;
}

TEST(Synth, MasksAreNonEmptyExactlyInTheClutteredTrainingViews) {
  TempDir t;
  const auto d = tiny("tiny_distractors.json");
  ASSERT_EQ(d.views.count, 16);
  const auto report = generate(d, t.path() / "s");
  const std::set<std::string> expected = expected_cluttered(16, d.distractors.clutter_ratio);
  ASSERT_EQ(expected.size(), 7u);  // round(0.5 · 14)
  EXPECT_EQ(std::set<std::string>(report.cluttered_views.begin(), report.cluttered_views.end()), expected);
  for (int k = 0; k < 16; ++k) {
    const std::string name = synth::view_name(k, 16);
    const fs::path mask_file = t.path() / "s" / "distractor_masks" / name;
    const std::string images = bytes_of(t.path() / "s" / "images" / name),
                      clean = bytes_of(t.path() / "s" / "clean" / name);
    if (k % 8 == 0) {  // test view: no mask, no distractors
      EXPECT_FALSE(fs::exists(mask_file)) << name;
      EXPECT_EQ(images, clean) << name;
      continue;
    }
    const FloatImage mask = read_image_rgb(mask_file);
    EXPECT_EQ(any_nonzero(mask), expected.count(name) == 1) << name;
    if (!expected.count(name)) {
      EXPECT_EQ(images, clean) << name << ": no effect applies, so the photo is the clean image";
      continue;
    }
    // Under the mask the photo shows the distractor; away from it (and its edge) the clean scene.
    const FloatImage photo = read_image_rgb(t.path() / "s" / "images" / name);
    const FloatImage still = read_image_rgb(t.path() / "s" / "clean" / name);
    int masked = 0, masked_changed = 0, far_changed = 0;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        const size_t i = static_cast<size_t>(y * 64 + x) * 3;
        bool changed = false;
        for (int c = 0; c < 3; ++c) changed |= photo.pixels[i + c] != still.pixels[i + c];
        bool near_mask = false;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = std::clamp(x + dx, 0, 63), yy = std::clamp(y + dy, 0, 47);
            near_mask |= mask.pixels[static_cast<size_t>(yy * 64 + xx) * 3] > 0.5f;
          }
        if (mask.pixels[i] > 0.5f) {
          ++masked;
          masked_changed += changed;
        } else if (!near_mask) {
          far_changed += changed;
        }
      }
    EXPECT_GT(masked, 10) << name;
    EXPECT_GE(masked_changed, 0.95 * masked) << name;
    EXPECT_LE(far_changed, 3) << name << ": only slivers below one pixel may change away from the mask";
  }
}

// Tracks: runs of 3 consecutive training views (0001–0003, 0004–0006, 0007 0009 0010, …) show
// the same objects at the same place in the frame, so their masks agree; the next run draws
// new objects. One sample per pixel, and nothing static stands between these cameras and their
// distractors, so within a run the masks should agree but for rounding at the silhouettes.
TEST(Synth, DistractorTracksRepeatTheSameObjectsInTheFrameForConsecutiveTrainingViews) {
  TempDir t;
  generate(tiny("tiny_distractors.json", {{"distractors.clutter_ratio", 1.0},
                                          {"distractors.track_length", 3},
                                          {"supersampling", 1},
                                          {"points.count", 0}}),
           t.path() / "s");
  std::vector<FloatImage> masks;
  for (int k = 0; k < 16; ++k)
    if (k % 8 != 0) masks.push_back(read_image_rgb(t.path() / "s" / "distractor_masks" / synth::view_name(k, 16)));
  ASSERT_EQ(masks.size(), 14u);
  const auto iou = [](const FloatImage& a, const FloatImage& b) {
    double both = 0, either = 0;
    for (size_t i = 0; i < a.pixels.size(); i += 3) {
      const bool x = a.pixels[i] > 0.5f, y = b.pixels[i] > 0.5f;
      both += x && y, either += x || y;
    }
    return either > 0 ? both / either : 1.0;
  };
  for (size_t j = 0; j < masks.size(); ++j) {
    ASSERT_TRUE(any_nonzero(masks[j])) << j;
    if (j % 3 != 0) {
      EXPECT_GT(iou(masks[j], masks[j - j % 3]), 0.9) << "training view " << j << " left its track";
    } else if (j > 0) {
      EXPECT_LT(iou(masks[j], masks[j - 3]), 0.5) << "training view " << j << " repeats the last track";
    }
  }
}

TEST(Synth, WithOneSamplePerPixelTheMaskIsExactlyWhereThePhotoShowsADistractor) {
  TempDir t;
  const auto report =
      generate(tiny("tiny_distractors.json", {{"supersampling", 1}, {"points.count", 0}}), t.path() / "s");
  ASSERT_FALSE(report.cluttered_views.empty());
  for (const std::string& name : report.cluttered_views) {
    const FloatImage mask = read_image_rgb(t.path() / "s" / "distractor_masks" / name);
    const FloatImage photo = read_image_rgb(t.path() / "s" / "images" / name);
    const FloatImage still = read_image_rgb(t.path() / "s" / "clean" / name);
    int disagree = 0, masked = 0;
    for (size_t p = 0; p < mask.pixels.size() / 3; ++p) {
      bool changed = false;
      for (size_t c = 0; c < 3; ++c) changed |= photo.pixels[p * 3 + c] != still.pixels[p * 3 + c];
      masked += mask.pixels[p * 3] > 0.5f;
      disagree += changed != (mask.pixels[p * 3] > 0.5f);
    }
    EXPECT_GT(masked, 10) << name;
    EXPECT_LE(disagree, 1) << name << ": a distractor may match the scene's 8-bit color by chance, rarely";
  }
}

TEST(Synth, ClutterRatioIsHonoured) {
  for (const double ratio : {0.0, 0.2, 0.6, 1.0}) {
    TempDir t;
    const auto d = tiny("tiny_distractors.json", {{"distractors.clutter_ratio", ratio}, {"points.count", 0}});
    const auto report = generate(d, t.path() / "s");
    const auto expected = expected_cluttered(16, ratio);
    EXPECT_EQ(std::set<std::string>(report.cluttered_views.begin(), report.cluttered_views.end()), expected) << ratio;
    size_t non_empty = 0;
    for (const auto& e : fs::directory_iterator(t.path() / "s" / "distractor_masks"))
      non_empty += any_nonzero(read_image_rgb(e.path()));
    EXPECT_EQ(non_empty, static_cast<size_t>(std::lround(ratio * 14))) << ratio;
  }
}

TEST(Synth, NoEffectsMeansNoEffectsWork) {
  TempDir t;
  const auto report = generate(tiny("tiny_clean.json"), t.path() / "s");
  EXPECT_EQ(report.distractor_ray_tests, 0u);
  EXPECT_EQ(report.sky_evaluations, 0u);
  EXPECT_EQ(report.exposure_pixels, 0u);
  EXPECT_EQ(report.noise_pixels, 0u);
  EXPECT_TRUE(report.cluttered_views.empty());
  for (int k = 0; k < 8; ++k) {
    const std::string name = synth::view_name(k, 8);
    EXPECT_EQ(bytes_of(t.path() / "s" / "images" / name), bytes_of(t.path() / "s" / "clean" / name)) << name;
    if (k % 8 != 0) {
      EXPECT_FALSE(any_nonzero(read_image_rgb(t.path() / "s" / "distractor_masks" / name))) << name;
    }
  }
}

TEST(Synth, EachEffectWorksAlone) {
  struct Case {
    json patch;
    bool changes_test_views;
  };
  const std::vector<Case> cases{{{{"noise.sigma", 0.03}}, true},
                                {{{"exposure.stops", 0.5}, {"exposure.white_balance", 0.1}}, false},
                                {{{"sky.enabled", true}, {"views.height", 0.2}}, true}};
  for (const Case& c : cases) {
    TempDir t;
    const auto report = generate(tiny("tiny_clean.json", c.patch), t.path() / "s");
    const bool noise = c.patch.contains("noise.sigma"), exposure = c.patch.contains("exposure.stops");
    const bool sky = c.patch.contains("sky.enabled");
    EXPECT_EQ(report.noise_pixels > 0, noise) << c.patch;
    EXPECT_EQ(report.exposure_pixels > 0, exposure) << c.patch;
    EXPECT_EQ(report.sky_evaluations > 0, sky) << c.patch;
    EXPECT_EQ(report.distractor_ray_tests, 0u) << c.patch;
    for (int k = 0; k < 8; ++k) {
      const std::string name = synth::view_name(k, 8);
      const bool same = bytes_of(t.path() / "s" / "images" / name) == bytes_of(t.path() / "s" / "clean" / name);
      // The sky is part of the static scene: it is in the clean images too.
      const bool photo_effect = !sky && (k % 8 != 0 || c.changes_test_views);
      EXPECT_EQ(same, !photo_effect) << c.patch << " " << name;
    }
    if (exposure) {  // the photo is the clean image times a per-channel gain within the range
      const FloatImage photo = read_image_rgb(t.path() / "s" / "images" / "0003.png");
      const FloatImage still = read_image_rgb(t.path() / "s" / "clean" / "0003.png");
      for (int ch = 0; ch < 3; ++ch) {
        double a = 0, b = 0;
        for (size_t i = static_cast<size_t>(ch); i < photo.pixels.size(); i += 3)
          if (photo.pixels[i] < 0.98f) a += photo.pixels[i], b += still.pixels[i];
        EXPECT_GE(a / b, std::exp2(-0.5) * 0.9 - 0.02);
        EXPECT_LE(a / b, std::exp2(0.5) * 1.1 + 0.02);
      }
    }
  }
}

TEST(Synth, SameSeedSameBytesAnyThreadCountDifferentSeedDifferentScene) {
  TempDir t;
  const auto d =
      tiny("tiny_distractors.json", {{"noise.sigma", 0.02}, {"exposure.stops", 0.3}, {"views.position_jitter", 0.1}});
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  generate(d, t.path() / "a");
  omp_set_num_threads(std::max(2, threads));
  generate(d, t.path() / "b");
  omp_set_num_threads(threads);
  const auto a = tree(t.path() / "a"), b = tree(t.path() / "b");
  ASSERT_EQ(a.size(), 16u * 2 + 14 + 3 + 3);  // images, clean, masks, sparse, lists + scene.json
  EXPECT_TRUE(a == b);

  generate(synth::apply_description(d, {{"seed", d.seed + 1}}, "test"), t.path() / "c");
  const auto c = tree(t.path() / "c");
  for (const std::string f : {"images/0001.png", "images/0008.png", "sparse/0/images.bin", "sparse/0/points3D.bin"})
    EXPECT_NE(a.at(f), c.at(f)) << f;
}

TEST(Synth, CheckedInDescriptionsLoadAndLayerOnTheirBase) {
  for (const auto& e : fs::directory_iterator(kDescriptions))
    if (e.path().extension() == ".json") {
      EXPECT_NO_THROW(synth::load_description(e.path())) << e.path();
    }
  const auto bench = synth::load_description(kDescriptions / "bench.json");
  const int train = bench.views.count - (bench.views.count + 7) / 8;
  EXPECT_GE(train, 40);
  EXPECT_LE(train, 60);
  EXPECT_EQ(bench.distractors.clutter_ratio, 1.0);
  EXPECT_EQ(bench.camera.width, 500);
  EXPECT_EQ(bench.camera.height, 375);
  for (const int pct : {0, 20, 40, 60, 80, 100}) {
    char file[64];
    std::snprintf(file, sizeof file, "bench_clutter_%03d.json", pct);
    EXPECT_EQ(synth::load_description(kDescriptions / file),
              synth::apply_description(bench, {{"distractors", {{"clutter_ratio", pct / 100.0}}}}, "test"))
        << file;
  }
  EXPECT_EQ(
      synth::load_description(kDescriptions / "bench_1080p_300.json"),
      synth::apply_description(
          bench, {{"camera", {{"width", 1920}, {"height", 1080}}}, {"views", {{"count", 300}}}, {"supersampling", 1}},
          "test"));
}

TEST(Synth, DescriptionErrorsNameTheFileAndTheKey) {
  TempDir t;
  const auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(t.path() / name) << text;
    return t.path() / name;
  };
  const auto expect_error = [&](const fs::path& file, const std::vector<std::string>& parts) {
    const std::string msg = error_of([&] { synth::load_description(file); });
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' missing in: " << msg;
  };
  expect_error(write("unknown.json", R"({"camera": {"widht": 64}})"), {"camera.widht", "unknown key"});
  expect_error(write("top.json", R"({"colour": 1})"), {"'colour'", "unknown key"});
  expect_error(write("dotted.json", R"({"distractors.ratio": 0.5})"), {"distractors.ratio"});
  expect_error(write("small.json", R"({"camera": {"width": 3}})"), {"camera.width", "got 3"});
  expect_error(write("type.json", R"({"views": {"count": "eight"}})"), {"views.count", "\"eight\""});
  expect_error(write("ratio.json", R"({"distractors": {"clutter_ratio": 1.5}})"), {"distractors.clutter_ratio", "1.5"});
  expect_error(write("range.json", R"({"distractors": {"per_view": [3, 1]}})"), {"distractors.per_view", "min <= max"});
  expect_error(write("shape.json", R"({"world": {"objects": [{"shape": "cone"}]}})"),
               {"world.objects[0].shape", "cone"});
  expect_error(write("pinhole.json", R"({"camera": {"distortion": [0.1, 0, 0, 0]}})"), {"camera.distortion", "OPENCV"});
  expect_error(write("syntax.json", R"({"seed": )"), {"not valid JSON"});
  expect_error(write("missing_base.json", R"({"base": "nowhere.json"})"), {"nowhere.json", "does not exist"});
  write("loop_a.json", R"({"base": "loop_b.json"})");
  expect_error(write("loop_b.json", R"({"base": "loop_a.json"})"), {"loops"});
  // An error in a base file names the base file.
  const fs::path bad_base = write("bad_base.json", R"({"noise": {"sigma": -1}})");
  const std::string msg =
      error_of([&] { synth::load_description(write("child.json", R"({"base": "bad_base.json"})")); });
  EXPECT_NE(msg.find(bad_base.string() + ": key 'noise.sigma'"), std::string::npos) << msg;
  EXPECT_NE(error_of([&] { synth::load_description(t.path() / "absent.json"); }).find("absent.json"),
            std::string::npos);
}

TEST(Synth, OutputFolderIsOnlyReplacedWhenAsked) {
  TempDir t;
  const auto d = tiny("tiny_clean.json", {{"points.count", 50}});
  fs::create_directories(t.path() / "other");
  std::ofstream(t.path() / "other" / "keep.txt") << "user file";
  EXPECT_NE(error_of([&] { generate(d, t.path() / "other"); }).find("not empty"), std::string::npos);

  generate(d, t.path() / "s");
  std::ofstream(t.path() / "s" / "notes.txt") << "mine";
  EXPECT_NE(error_of([&] { generate(d, t.path() / "s"); }).find("--overwrite"), std::string::npos);
  synth::GenerateOptions o;
  o.out = t.path() / "s";
  o.overwrite = true;
  synth::generate_scene(synth::apply_description(d, {{"views.count", 4}}, "test"), o);
  EXPECT_FALSE(fs::exists(t.path() / "s" / "images" / "0005.png")) << "stale views of the earlier scene are removed";
  EXPECT_TRUE(fs::exists(t.path() / "s" / "notes.txt")) << "files the generator did not write are kept";
}
