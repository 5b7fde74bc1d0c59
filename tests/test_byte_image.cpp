// core/image.hpp's 8-bit photos: conversions checked against OpenImageIO's own reading of
// an 8-bit file and against double-precision references.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "desplat/core/image.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/jobs/training_run.hpp"
#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"
#include "support/temp_dir.hpp"

namespace desplat {
namespace {

// Every byte, written as an 8-bit PNG and read back through the float reader the scene
// loader uses: to_bytes gives each byte back, and byte_to_float gives the float the reader gave.
TEST(ByteImage, EveryByteOfAnEightBitFileSurvivesTheRoundTrip) {
  testing::TempDir dir("byte_image");
  std::vector<uint8_t> bytes(256 * 3);
  for (int b = 0; b < 256; ++b)
    bytes[3 * b] = uint8_t(b), bytes[3 * b + 1] = uint8_t(255 - b), bytes[3 * b + 2] = uint8_t(b / 2);
  const auto path = dir.path() / "all.png";
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path.string(), OIIO::ImageSpec(256, 1, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, bytes.data()));
  out->close();
  const FloatImage read = read_image_rgb(path);
  const ByteImage held = to_bytes(read);
  EXPECT_EQ(held.pixels, bytes);
  for (size_t i = 0; i < bytes.size(); ++i) EXPECT_EQ(byte_to_float(held.pixels[i]), read.pixels[i]) << i;
  const FloatImage back = to_float(held);
  EXPECT_EQ(back.pixels, read.pixels);
}

// Reference: the nearest byte in double precision, after clamping; NaN is 0. Values away
// from a tie by more than float rounding must agree exactly.
TEST(ByteImage, ToBytesRoundsToTheNearestByteAndClamps) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-0.3f, 1.3f);
  FloatImage img{50, 20, 3, std::vector<float>(3000)};
  for (float& v : img.pixels) v = u(rng);
  img.pixels[0] = std::numeric_limits<float>::quiet_NaN();
  img.pixels[1] = std::numeric_limits<float>::infinity();
  img.pixels[2] = -std::numeric_limits<float>::infinity();
  const ByteImage b = to_bytes(img);
  ASSERT_EQ(b.pixels.size(), img.pixels.size());
  EXPECT_EQ(b.pixels[0], 0);
  EXPECT_EQ(b.pixels[1], 255);
  EXPECT_EQ(b.pixels[2], 0);
  int checked = 0;
  for (size_t i = 3; i < img.pixels.size(); ++i) {
    const double x = std::clamp(double(img.pixels[i]), 0.0, 1.0) * 255.0;
    if (std::abs(x - std::floor(x) - 0.5) < 1e-4) continue;  // a tie: either neighbour is right
    EXPECT_EQ(int(b.pixels[i]), int(std::floor(x + 0.5))) << img.pixels[i];
    ++checked;
  }
  EXPECT_GT(checked, 2900);
}

// Reference: the block mean in double, rounded half up; odd sizes drop the partial blocks.
TEST(ByteImage, DownscaleIsTheRoundedBlockMean) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> u(0, 255);
  for (const int factor : {1, 2, 3, 4}) {
    ByteImage img{37, 23, 3, std::vector<uint8_t>(37 * 23 * 3)};
    for (uint8_t& v : img.pixels) v = uint8_t(u(rng));
    const ByteImage small = downscale_bytes(img, factor);
    ASSERT_EQ(small.width, 37 / factor);
    ASSERT_EQ(small.height, 23 / factor);
    for (int y = 0; y < small.height; ++y)
      for (int x = 0; x < small.width; ++x)
        for (int c = 0; c < 3; ++c) {
          double sum = 0;
          for (int dy = 0; dy < factor; ++dy)
            for (int dx = 0; dx < factor; ++dx)
              sum += img.pixels[(size_t(y * factor + dy) * 37 + x * factor + dx) * 3 + c];
          const int want = int(std::floor(sum / (factor * factor) + 0.5));
          EXPECT_EQ(int(small.pixels[(size_t(y) * small.width + x) * 3 + c]), want) << factor << " " << x << "," << y;
        }
  }
  // A block of two values a tie apart rounds up: (10 + 11 + 10 + 11) / 4 = 10.5 → 11.
  const ByteImage tie{2, 2, 1, {10, 11, 10, 11}};
  EXPECT_EQ(downscale_bytes(tie, 2).pixels, std::vector<uint8_t>{11});
  EXPECT_THROW(downscale_bytes(tie, 0), std::invalid_argument);
}

TEST(ByteImage, ConvertingIntoAWronglySizedBufferIsAnError) {
  const ByteImage img{2, 2, 3, std::vector<uint8_t>(12, 7)};
  std::vector<float> small(11);
  EXPECT_THROW(to_float(img, small), std::invalid_argument);
}

// A capture with one 16-bit photo: training holds it in 8 bits and says so once, naming it;
// the same capture in 8 bits loads without a word, and both hold the same bytes.
TEST(ByteImage, LoadingADeeperPhotoWarnsThatItIsRounded) {
  testing::TempDir dir("byte_image_scene"), cache("byte_image_cache");
  const TrainingData data = test::synthetic_training_data(8, 64, 48, 2);
  test::write_scene_folder(dir.path(), data);
  auto load = [&](std::vector<std::string>& warnings) {
    SceneOptions o;
    o.cache_dir = cache.path();
    o.on_warning = [&](const std::string& w) { warnings.push_back(w); };
    return load_training_data(load_colmap_scene(dir.path(), o));
  };
  std::vector<std::string> plain;
  const TrainingData eight = load(plain);
  EXPECT_TRUE(plain.empty()) << plain.front();

  // view_1 again, as 16 bits per channel: each byte b becomes 257·b + 1 (not a whole byte).
  const ByteImage& photo = data.train.at(0).image;
  ASSERT_EQ(data.train[0].name, "view_1");
  std::vector<uint16_t> deep(photo.pixels.size());
  for (size_t i = 0; i < deep.size(); ++i) deep[i] = uint16_t(257 * photo.pixels[i] + (photo.pixels[i] < 255 ? 1 : -1));
  const auto path = dir.path() / "images" / "view_1.png";
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path.string(), OIIO::ImageSpec(photo.width, photo.height, 3, OIIO::TypeDesc::UINT16)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, deep.data()));
  out->close();
  std::vector<std::string> warnings;
  const TrainingData sixteen = load(warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_CONTAINS(warnings[0], "1 of 8 photos (first: view_1.png) hold more than 8 bits per channel");
  EXPECT_CONTAINS(warnings[0], "rounds them to 8 bits");
  ASSERT_EQ(sixteen.train.size(), eight.train.size());
  for (size_t v = 0; v < eight.train.size(); ++v)
    EXPECT_EQ(sixteen.train[v].image.pixels, eight.train[v].image.pixels) << v;
}

}  // namespace
}  // namespace desplat
