// desplat_occlude's library job (synth/occluders.hpp) on the real fox capture (read-only
// input): occluders pasted into training views, with their masks and report.
//
// Independent expectations: the input files' own bytes and decoded pixels; the colours, boxes
// and source patches listed in occluders.json; the masks loaded back through io/masks.hpp.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "desplat/io/colmap.hpp"
#include "desplat/io/masks.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/synth/occluders.hpp"
#include "support/expect.hpp"
#include "support/fox_scene.hpp"
#include "support/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace desplat;
using desplat::testing::error_of;
using desplat::testing::fox_dir;
using desplat::testing::slurp;
using desplat::testing::TempDir;

namespace {

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
  for (const auto& e : fs::directory_iterator(fox_dir() / "images")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  std::map<std::string, bool> roles;
  for (size_t i = 0; i < names.size(); ++i) roles[names[i]] = i % 8 == 0;
  return roles;
}

constexpr double kFraction = 0.2;

OccludeOptions fox_options(const fs::path& out, uint64_t seed = 3) {
  OccludeOptions o;
  o.data_dir = fox_dir();
  o.out_dir = out;
  o.fraction = kFraction;
  o.seed = seed;
  return o;
}

// One run shared by the fox tests (the job takes about a second).
class OccludeFox : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir("occlude_fox");
    report_ = new OccludeReport(occlude_scene(fox_options(dir_->path() / "out")));
  }
  static void TearDownTestSuite() {
    delete report_;
    delete dir_;
  }
  static fs::path out() { return dir_->path() / "out"; }
  static inline TempDir* dir_ = nullptr;
  static inline OccludeReport* report_ = nullptr;
};

TEST_F(OccludeFox, CopiesTheModelAndUntouchedViewsByteForByte) {
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    EXPECT_EQ(slurp(out() / "sparse/0" / f), slurp(fox_dir() / "sparse/0" / f)) << f;
  const auto is_test = fox_is_test();
  ASSERT_EQ(report_->views.size(), is_test.size());
  size_t train = 0, occluded = 0;
  for (const OccludedView& v : report_->views) {
    ASSERT_TRUE(is_test.count(v.name)) << v.name;
    EXPECT_EQ(v.role, is_test.at(v.name) ? ViewRole::Test : ViewRole::Train) << v.name;
    train += v.role == ViewRole::Train;
    occluded += v.occluded;
    EXPECT_TRUE(!v.occluded || v.role == ViewRole::Train) << v.name;
    const bool same = slurp(out() / "images" / v.name) == slurp(fox_dir() / "images" / v.name);
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
        for (const Occluder& o : v.occluders)
          in_a_box |= x >= o.box[0] && x < o.box[2] && y >= o.box[1] && y < o.box[3];
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
    const Decoded before = decode(fox_dir() / "images" / v.name), after = decode(out() / "images" / v.name);
    const Decoded m = decode(out() / "distractor_masks" / fs::path(v.name).replace_extension(".png"));
    ASSERT_EQ(before.width, after.width);
    ASSERT_EQ(before.height, after.height);
    ASSERT_EQ(after.channels, 3);
    std::vector<uint8_t> block_touched(size_t((m.width + 7) / 8) * ((m.height + 7) / 8), 0);
    const auto block = [&](int x, int y) -> uint8_t& {
      return block_touched[size_t(y / 8) * ((m.width + 7) / 8) + x / 8];
    };
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
      source = decode(fox_dir() / "images" / o.source_image);
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
        if (!deep_inside(bx, by) || !deep_inside(bx + 8, by) || !deep_inside(bx, by + 8) ||
            !deep_inside(bx + 8, by + 8))
          continue;
        for (int y = by; y < by + 8; ++y)
          for (int x = bx; x < bx + 8; ++x)
            for (int ch = 0; ch < 3; ++ch) {
              const float expected = o.source_image.empty() ? o.color[ch] / 255.0f
                                                            : source.at(x + o.source_box[0] - o.box[0],
                                                                        y + o.source_box[1] - o.box[1], ch);
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
  TempDir cache("occlude_fox_cache");
  SceneOptions o;
  o.downscale = 2;
  o.cache_dir = cache.path();
  const Scene occluded = load_colmap_scene(out(), o);
  const Scene original = load_colmap_scene(fox_dir(), o);
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
    if (m.pixels[p] > 0.5f)
      n_in += 1, changed_in += diff > 24.0f / 255;
    else if (m.pixels[p] == 0.0f)
      n_out += 1, changed_out += diff > 24.0f / 255;
  }
  ASSERT_GT(n_in, 0);
  EXPECT_GT(changed_in / n_in, 0.5);
  EXPECT_LT(changed_out / n_out, 0.01);  // measured 0: only JPEG noise outside, far below 24/255
}

TEST(OccludeScene, SameSeedSameFilesOtherSeedOtherOccluders) {
  TempDir dir("occlude_determinism");
  occlude_scene(fox_options(dir.path() / "a", 11));
  occlude_scene(fox_options(dir.path() / "b", 11));
  occlude_scene(fox_options(dir.path() / "c", 12));
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir.path() / "a")) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = e.path().lexically_relative(dir.path() / "a");
    EXPECT_EQ(slurp(e.path()), slurp(dir.path() / "b" / rel)) << rel;
    ++files;
  }
  EXPECT_EQ(files, 3 + 50 + 43 + 1u);  // model, images, training masks, occluders.json
  EXPECT_NE(slurp(dir.path() / "a/occluders.json"), slurp(dir.path() / "c/occluders.json"));
}

// Tracks: the training views, in name order, cut into runs of 4; a run is occluded whole or
// not at all, round(0.5 · 43 / 4) = 5 runs are, and every view of a run carries the same
// occluders and the same mask, with patches cut only from photos outside the run.
TEST(OccludeScene, TracksShareOccludersOverConsecutiveTrainingViews) {
  TempDir dir("occlude_tracks");
  OccludeOptions o = fox_options(dir.path() / "out");
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
  OccludeOptions one = fox_options(dir.path() / "one");
  one.track_length = 1;
  OccludeOptions def = fox_options(dir.path() / "default");
  const OccludeReport r1 = occlude_scene(one), r0 = occlude_scene(def);
  for (size_t i = 0; i < r0.views.size(); ++i) {
    EXPECT_EQ(r1.views[i].occluded, r0.views[i].occluded);
    EXPECT_EQ(slurp(dir.path() / "one/images" / r1.views[i].name),
              slurp(dir.path() / "default/images" / r0.views[i].name));
  }
}

TEST(OccludeScene, BadInputGivesOneClearError) {
  TempDir dir("occlude_errors");
  const auto error = [](const OccludeOptions& o) { return error_of<OccludeError>([&] { occlude_scene(o); }); };
  OccludeOptions o = fox_options(dir.path() / "out");
  o.fraction = 1.5;
  EXPECT_CONTAINS(error(o), "--fraction");
  o = fox_options(dir.path() / "out");
  o.coverage_min = 0.3;
  o.coverage_max = 0.2;
  EXPECT_CONTAINS(error(o), "--coverage-min");
  o = fox_options(dir.path() / "out");
  o.track_length = 0;
  EXPECT_CONTAINS(error(o), "--track");
  o = fox_options(fox_dir() / "occluded");
  EXPECT_CONTAINS(error(o), "must not be the input folder");
  o = fox_options(fox_dir());
  EXPECT_CONTAINS(error(o), "must not be the input folder");
  o = fox_options(dir.path() / "out");
  o.data_dir = dir.path() / "nowhere";
  EXPECT_CONTAINS(error(o), "nowhere");
  EXPECT_FALSE(fs::exists(dir.path() / "out" / "images"));  // nothing written on bad input

  // A capture with a registered image that has no file.
  const fs::path broken = dir.path() / "broken";
  fs::create_directories(broken / "images");
  fs::copy(fox_dir() / "sparse", broken / "sparse", fs::copy_options::recursive);
  o = fox_options(dir.path() / "out2");
  o.data_dir = broken;
  const std::string missing = error(o);
  EXPECT_CONTAINS(missing, (broken / "images").string());
  EXPECT_CONTAINS(missing, "no file for registered image");

  // A second run into the same folder needs --overwrite.
  o = fox_options(dir.path() / "out3");
  o.fraction = 0;
  occlude_scene(o);
  EXPECT_CONTAINS(error(o), "--overwrite");
  o.overwrite = true;
  EXPECT_EQ(occlude_scene(o).views.size(), 50u);
}

}  // namespace
