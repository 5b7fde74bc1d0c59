// Ordered frames or an unordered collection (sfm.hpp, "Ordered frames or an unordered
// collection"): the thumbnail against hand-computed values, the judgement against hand-built
// sequences, and the real fox video in its order and shuffled.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "desplat/sfm/sfm.hpp"
#include "support/fox_scene.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;
using sfm::kOrderThumbnailSize;
constexpr int S = kOrderThumbnailSize;

FloatImage rgb(int w, int h, float (*f)(int x, int y)) {
  FloatImage im{w, h, 3, std::vector<float>(size_t(w) * h * 3)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) im.pixels[(size_t(y) * w + x) * 3 + c] = f(x, y);
  return im;
}

TEST(CaptureOrder, ThumbnailIsTheNormalizedBoxMeanOfEachChannel) {
  // 32×16 px, left half 0.2, right half 0.6 in every channel: each cell averages 4×2 px of one
  // half, so each plane holds 0.2 and 0.6 in equal numbers; normalized, −1 and +1 exactly.
  const FloatImage halves = rgb(32, 16, [](int x, int) { return x < 16 ? 0.2f : 0.6f; });
  const std::vector<float> t = sfm::order_thumbnail(halves);
  ASSERT_EQ(t.size(), size_t(sfm::kOrderThumbnailValues));
  for (int ch = 0; ch < 3; ++ch)
    for (int y = 0; y < S; ++y)
      for (int x = 0; x < S; ++x)
        EXPECT_NEAR(t[(ch * S + y) * S + x], x < S / 2 ? -1.0f : 1.0f, 1e-5f) << ch << ":" << x << "," << y;
  // Exposure and gain do not count: 0.5·I + 0.1 gives the same thumbnail.
  FloatImage darker = halves;
  for (float& v : darker.pixels) v = 0.5f * v + 0.1f;
  const std::vector<float> u = sfm::order_thumbnail(darker);
  for (int i = 0; i < sfm::kOrderThumbnailValues; ++i) EXPECT_NEAR(u[i], t[i], 1e-4f);
  // Neither does white balance: scaling one channel leaves its normalized plane as it was.
  FloatImage warmer = halves;
  for (size_t i = 0; i < warmer.pixels.size(); i += 3) warmer.pixels[i] *= 1.3f;
  const std::vector<float> w = sfm::order_thumbnail(warmer);
  for (int i = 0; i < sfm::kOrderThumbnailValues; ++i) EXPECT_NEAR(w[i], t[i], 1e-4f);
  // A flat image carries nothing to compare: all zeros, no NaN from a zero variance.
  // (20×6 px: fewer rows than cells, so rows are shared between cells, none left empty.)
  for (float v : sfm::order_thumbnail(rgb(20, 6, [](int, int) { return 0.7f; }))) EXPECT_EQ(v, 0.0f);
  for (float v : sfm::order_thumbnail(FloatImage{})) EXPECT_EQ(v, 0.0f);
  // 4×2 px, pixel (x, y) = x: cell column cx reads pixel column ⌊cx/2⌋, so each plane holds
  // the four values 0..3 in equal numbers, normalized: (x − 1.5) / √1.25.
  const std::vector<float> tiny = sfm::order_thumbnail(rgb(4, 2, [](int x, int) { return float(x); }));
  for (int cx = 0; cx < S; ++cx) EXPECT_NEAR(tiny[3 * S + cx], (cx / 2 - 1.5) / std::sqrt(1.25), 1e-5) << cx;
}

TEST(CaptureOrder, MediansOfNeighboursAndOfPhotosHalfTheCaptureApart) {
  // Thumbnails holding one value v in every cell: any shift compares v with v', so the distance
  // of two of them is |v − v'|.
  const auto judged = [](std::vector<float> v) {
    std::vector<std::vector<float>> t;
    for (float x : v) t.emplace_back(sfm::kOrderThumbnailValues, x);
    return sfm::judge_capture_order(t);
  };
  // v = 0, 1, 2, 3: neighbours differ by 1 (median 1); half apart, (0,2) and (1,3), by 2.
  sfm::CaptureOrder r = judged({0, 1, 2, 3});
  EXPECT_NEAR(r.neighbour_distance, 1.0, 1e-6);
  EXPECT_NEAR(r.far_distance, 2.0, 1e-6);
  EXPECT_TRUE(r.ordered);  // ratio 0.5 ≤ 0.8
  EXPECT_NE(r.reason.find("taken in order"), std::string::npos) << r.reason;
  // v = 0, 5, 6, 11: neighbours 5, 1, 5 (median 5); half apart 6, 6: ratio 5/6 > 0.8.
  r = judged({0, 5, 6, 11});
  EXPECT_NEAR(r.neighbour_distance, 5.0, 1e-6);
  EXPECT_NEAR(r.far_distance, 6.0, 1e-6);
  EXPECT_FALSE(r.ordered);
  EXPECT_NE(r.reason.find("not in file-name order"), std::string::npos) << r.reason;
  // All alike (far distance 0): nothing says they are in order.
  EXPECT_FALSE(judged({1, 1, 1, 1, 1}).ordered);
  // Fewer than four photos: no judgement, and the reason says so.
  r = judged({0, 1, 2});
  EXPECT_FALSE(r.ordered);
  EXPECT_NE(r.reason.find("too few photos"), std::string::npos) << r.reason;
  // A thumbnail of the wrong length is refused, not read past its end.
  std::vector<std::vector<float>> wrong(4, std::vector<float>(sfm::kOrderThumbnailValues, 0.0f));
  wrong[2].resize(10);
  EXPECT_THROW(sfm::judge_capture_order(wrong), std::invalid_argument);
}

// The shift search: a view moved by one cell is at distance 0 from the original; moved by two
// it is not (kOrderMaxShift = 1).
TEST(CaptureOrder, AOneCellShiftIsForgiven) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> value(-1.0f, 1.0f);
  std::vector<float> wall(3 * S * (S + 2));  // three planes of S rows × (S + 2) columns
  for (float& v : wall) v = value(rng);
  const auto window = [&](int offset) {  // the S×S view starting `offset` columns in
    std::vector<float> t(sfm::kOrderThumbnailValues);
    for (int ch = 0; ch < 3; ++ch)
      for (int y = 0; y < S; ++y)
        for (int x = 0; x < S; ++x) t[(ch * S + y) * S + x] = wall[(ch * S + y) * (S + 2) + x + offset];
    return t;
  };
  // Photos a, b, a, b: every neighbour pair is (a, b), so the neighbour median is d(a, b).
  const auto distance = [](const std::vector<float>& a, const std::vector<float>& b) {
    return sfm::judge_capture_order({a, b, a, b}).neighbour_distance;
  };
  EXPECT_NEAR(distance(window(0), window(1)), 0.0, 1e-6);
  EXPECT_GT(distance(window(0), window(2)), 0.3);
}

// A camera panning along a long wall of random tiles (8×8 px each, three colours): photo k sees
// 64×32 px of it from x = 3k on, so neighbours share most of their view and photos half the
// sequence apart share none.
std::vector<std::vector<float>> panning_sequence(int n) {
  const int tiles_across = (64 + 3 * n) / 8 + 1;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> tone(0.0f, 1.0f);
  std::vector<float> tiles(size_t(tiles_across) * 4 * 3);
  for (float& t : tiles) t = tone(rng);
  std::vector<std::vector<float>> thumbs;
  for (int k = 0; k < n; ++k) {
    FloatImage im{64, 32, 3, std::vector<float>(64 * 32 * 3)};
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 64; ++x)
        for (int c = 0; c < 3; ++c)
          im.pixels[(size_t(y) * 64 + x) * 3 + c] = tiles[(((x + 3 * k) / 8) * 4 + y / 8) * 3 + c];
    thumbs.push_back(sfm::order_thumbnail(im));
  }
  return thumbs;
}

TEST(CaptureOrder, APanningSequenceIsOrderedAndShuffledItIsNot) {
  std::vector<std::vector<float>> thumbs = panning_sequence(40);
  const sfm::CaptureOrder in_order = sfm::judge_capture_order(thumbs);
  EXPECT_TRUE(in_order.ordered) << in_order.reason;
  for (unsigned seed : {1u, 2u, 3u}) {
    std::vector<std::vector<float>> shuffled = thumbs;
    std::mt19937 rng(seed);
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    const sfm::CaptureOrder r = sfm::judge_capture_order(shuffled);
    EXPECT_FALSE(r.ordered) << "seed " << seed << ": " << r.reason;
  }
}

// The real capture: the fox's 50 photos are frames of one video, named in capture order.
TEST(CaptureOrder, TheFoxVideoIsOrderedAndItsFramesShuffledAreNot) {
  if (!testing::fox_available()) GTEST_SKIP() << "fox capture not found";
  const fs::path dir = testing::fox_dir() / "images";
  std::vector<fs::path> photos;
  for (const auto& e : fs::directory_iterator(dir)) photos.push_back(e.path().filename());
  std::sort(photos.begin(), photos.end());
  ASSERT_EQ(photos.size(), 50u);
  const sfm::CaptureOrder in_order = sfm::detect_capture_order(dir, photos);
  EXPECT_TRUE(in_order.ordered) << in_order.reason;
  for (unsigned seed : {1u, 2u, 3u}) {
    std::vector<fs::path> shuffled = photos;
    std::mt19937 rng(seed);
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    const sfm::CaptureOrder r = sfm::detect_capture_order(dir, shuffled);
    EXPECT_FALSE(r.ordered) << "seed " << seed << ": " << r.reason;
  }
  // A photo that cannot be read counts as flat; the judgement still runs.
  std::vector<fs::path> with_missing = photos;
  with_missing[10] = "no_such_photo.jpg";
  EXPECT_TRUE(sfm::detect_capture_order(dir, with_missing).ordered);
}

TEST(CaptureOrder, AutoMatcherFollowsCountAndOrder) {
  using sfm::Matcher;
  EXPECT_EQ(sfm::choose_matcher(Matcher::Auto, 100, true), Matcher::Exhaustive);        // few: every pair
  EXPECT_EQ(sfm::choose_matcher(Matcher::Auto, 101, true), Matcher::Sequential);        // many, in order
  EXPECT_EQ(sfm::choose_matcher(Matcher::Auto, 300, false), Matcher::Exhaustive);       // a large collection
  EXPECT_EQ(sfm::choose_matcher(Matcher::Sequential, 20, false), Matcher::Sequential);  // as asked
}

}  // namespace
}  // namespace desplat
