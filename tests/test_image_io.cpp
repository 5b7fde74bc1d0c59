// read_image_rgb on the formats users bring: 8- and 16-bit PNG, JPEG, float EXR,
// greyscale and RGBA files, written here directly with OpenImageIO at known values.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "desplat/io/image_io.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

fs::path temp(const std::string& name) { return fs::temp_directory_path() / ("desplat_imgio_" + name); }

template <typename T>
void write_raw(const fs::path& path, int w, int h, int channels, OIIO::TypeDesc type, const std::vector<T>& data) {
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(w, h, channels, type);
  spec.attribute("oiio:UnassociatedAlpha", 1);  // store RGBA bytes exactly as given
  ASSERT_TRUE(out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(type, data.data()));
  out->close();
}

TEST(ImageIo, SixteenBitPngKeepsItsPrecision) {
  std::vector<uint16_t> px = {0, 1, 65535, 32768, 12345, 999};  // 2×1 RGB
  write_raw(temp("16.png"), 2, 1, 3, OIIO::TypeDesc::UINT16, px);
  const FloatImage img = read_image_rgb(temp("16.png"));
  ASSERT_EQ(img.width, 2);
  for (size_t i = 0; i < px.size(); ++i) EXPECT_NEAR(img.pixels[i], px[i] / 65535.0, 1e-7) << i;
  fs::remove(temp("16.png"));
}

TEST(ImageIo, FloatExrIsReadAsStored) {
  std::vector<float> px = {0.25f, 0.5f, 0.75f, 1.0f, 0.0f, 0.125f};
  write_raw(temp("f.exr"), 1, 2, 3, OIIO::TypeDesc::FLOAT, px);
  const FloatImage img = read_image_rgb(temp("f.exr"));
  ASSERT_EQ(img.height, 2);
  for (size_t i = 0; i < px.size(); ++i) EXPECT_FLOAT_EQ(img.pixels[i], px[i]);
  fs::remove(temp("f.exr"));
}

TEST(ImageIo, GreyIsReplicatedAndAlphaDropped) {
  write_raw(temp("g.png"), 2, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{51, 204});
  FloatImage img = read_image_rgb(temp("g.png"));
  const std::vector<float> grey = {0.2f, 0.2f, 0.2f, 0.8f, 0.8f, 0.8f};
  for (size_t i = 0; i < grey.size(); ++i) EXPECT_NEAR(img.pixels[i], grey[i], 1e-7);
  write_raw(temp("a.png"), 1, 1, 4, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{255, 0, 51, 7});
  img = read_image_rgb(temp("a.png"));  // color as stored, not premultiplied by alpha
  const std::vector<float> rgb = {1.0f, 0.0f, 0.2f};
  for (size_t i = 0; i < rgb.size(); ++i) EXPECT_NEAR(img.pixels[i], rgb[i], 1e-7);
  fs::remove(temp("g.png"));
  fs::remove(temp("a.png"));
}

TEST(ImageIo, EightBitRoundTripThroughWriteImage) {
  FloatImage in{3, 2, 3, {}};
  for (int i = 0; i < 18; ++i) in.pixels.push_back(float(i * 15) / 255.0f);
  write_image(temp("rt.png"), in);
  const FloatImage back = read_image_rgb(temp("rt.png"));
  for (size_t i = 0; i < in.pixels.size(); ++i) EXPECT_NEAR(back.pixels[i], in.pixels[i], 1e-7);
  fs::remove(temp("rt.png"));
}

TEST(ImageIo, UnreadableFilesNameTheFile) {
  const fs::path bad = temp("bad.jpg");
  std::ofstream(bad) << "not an image";
  try {
    read_image_rgb(bad);
    FAIL() << "no error";
  } catch (const ImageError& e) {
    EXPECT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
  }
  fs::remove(bad);
  EXPECT_THROW(read_image_rgb(temp("missing.png")), ImageError);
}

}  // namespace
}  // namespace desplat
