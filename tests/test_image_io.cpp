// read_image_rgb on the formats users bring: 8- and 16-bit PNG, JPEG, float EXR,
// greyscale and RGBA files, written here directly with OpenImageIO at known values.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <csignal>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "desplat/io/image_io.hpp"
#include "desplat/io/photo_file.hpp"
#include "support/expect.hpp"
#include "support/fox_scene.hpp"
#include "support/temp_dir.hpp"

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

// A disk that fills up mid-write, simulated in this process: with SIGXFSZ ignored, a write
// past the soft RLIMIT_FSIZE fails with EFBIG, as one onto a full disk fails with ENOSPC.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    ::getrlimit(RLIMIT_FSIZE, &old_);
    const rlimit limited{bytes, old_.rlim_max};
    ::setrlimit(RLIMIT_FSIZE, &limited);
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &old_);
    std::signal(SIGXFSZ, old_handler_);
  }

 private:
  rlimit old_{};
  void (*old_handler_)(int) = nullptr;
};

FloatImage noise(int w, int h) {  // incompressible enough to be several kB as PNG
  FloatImage img{w, h, 3, {}};
  uint32_t state = 12345;
  for (int i = 0; i < w * h * 3; ++i) {
    state = state * 1664525u + 1013904223u;
    img.pixels.push_back(float(state >> 24) / 255.0f);
  }
  return img;
}

TEST(ImageIo, AFailedWriteIsAnErrorNamingTheFileAndKeepsTheOldOne) {
  testing::TempDir tmp;
  const fs::path kept = tmp.path() / "renders" / "view.png", fresh = tmp.path() / "renders" / "new.png";
  write_image(kept, noise(4, 4));
  const std::string before = testing::slurp(kept);
  const FloatImage big = noise(128, 128);
  std::vector<uint8_t> mask;
  for (float v : big.pixels) mask.push_back(static_cast<uint8_t>(v * 255));  // noise too
  mask.resize(128 * 128);
  std::string render_error, new_error, mask_error;
  {
    const FileSizeLimit limit(4096);
    render_error = testing::error_of<ImageError>([&] { write_image(kept, big); });
    new_error = testing::error_of<ImageError>([&] { write_image(fresh, big); });
    mask_error = testing::error_of<ImageError>([&] { write_mask_u8(fresh, 128, 128, mask.data()); });
  }
  EXPECT_CONTAINS(render_error, kept.string());
  EXPECT_CONTAINS(render_error, "File too large");  // the cause, as the system gives it
  EXPECT_CONTAINS(new_error, fresh.string());
  EXPECT_CONTAINS(mask_error, "cannot write the mask " + fresh.string());
  EXPECT_EQ(testing::slurp(kept), before);  // the old file, whole
  EXPECT_FALSE(fs::exists(fresh));          // no 0-byte or partial file
  for (const auto& entry : fs::directory_iterator(tmp.path() / "renders"))
    EXPECT_TRUE(entry.path() == kept) << "left behind: " << entry.path();

  write_image(fresh, big);  // without the limit the same writes succeed
  EXPECT_EQ(read_image_rgb(fresh).width, 128);
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

// A JPEG cut short decodes without an error in libjpeg (the missing rows come out grey), so
// read_image_rgb checks that the data reaches the end-of-image marker. The fox's camera
// JPEGs (EXIF thumbnails inside) must pass; each of them truncated must fail with the file
// named; data appended after the end marker (motion photos, vendor trailers) is allowed.
TEST(ImageIo, TruncatedJpegIsAnErrorThatNamesTheFile) {
  if (!testing::fox_available()) GTEST_SKIP() << "fox capture not found";
  std::vector<fs::path> photos;
  for (const auto& e : fs::directory_iterator(testing::fox_dir() / "images")) photos.push_back(e.path());
  ASSERT_GE(photos.size(), 10u);
  std::sort(photos.begin(), photos.end());
  photos.resize(10);
  for (const fs::path& photo : photos) {
    const FloatImage whole = read_image_rgb(photo);  // intact files read as before
    std::ifstream in(photo, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const size_t keep : {size_t(5000), bytes.size() / 2, bytes.size() - 2}) {
      const fs::path cut = temp("cut.jpg");
      std::ofstream(cut, std::ios::binary) << bytes.substr(0, keep);
      const std::string error = testing::error_of<ImageError>([&] { read_image_rgb(cut); });
      EXPECT_CONTAINS(error, cut.string());
      EXPECT_CONTAINS(error, "truncated");
      // The photo reader of the editing tools (desplat_occlude) refuses it too.
      EXPECT_CONTAINS(testing::error_of<ImageError>([&] { read_photo_file(cut); }), "truncated");
      fs::remove(cut);
    }
    const fs::path trailer = temp("trailer.jpg");
    std::ofstream(trailer, std::ios::binary) << bytes << std::string(700, '\0') << "vendor data \xff\xd8";
    EXPECT_EQ(read_image_rgb(trailer).pixels, whole.pixels) << photo;
    EXPECT_NO_THROW(read_photo_file(trailer));
    fs::remove(trailer);
  }
  // A JPEG written by OpenImageIO itself reads back.
  const fs::path own = temp("own.jpg");
  write_raw<uint8_t>(own, 16, 8, 3, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(16 * 8 * 3, 77));
  EXPECT_NO_THROW(read_image_rgb(own));
  fs::remove(own);
}

}  // namespace
}  // namespace desplat
