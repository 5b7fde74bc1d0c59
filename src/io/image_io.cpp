// Image reading and writing with OpenImageIO.
#include "desplat/io/image_io.hpp"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "desplat/io/jpeg_end.hpp"
#include "io/image_write_helpers.hpp"

namespace desplat {

FloatImage read_image_rgb(const std::filesystem::path& path) {
  // Keep color as stored: by default OpenImageIO premultiplies RGBA files by alpha.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path.string(), &config);
  if (!in) throw ImageError("cannot read image " + path.string() + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw ImageError("image " + path.string() + " has no pixels");
  std::vector<float> raw(size_t(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, raw.data()))
    throw ImageError("cannot decode image " + path.string() + ": " + in->geterror());
  if (std::string(in->format_name()) == "jpeg" && !jpeg_reaches_end_marker(path))
    throw ImageError("image " + path.string() +
                     " is truncated or damaged: its JPEG data ends before the end-of-image marker "
                     "(a decoder would fill the missing part with grey)");
  FloatImage img{spec.width, spec.height, 3, std::vector<float>(size_t(spec.width) * spec.height * 3)};
  const size_t pixels = size_t(spec.width) * spec.height;
  for (size_t p = 0; p < pixels; ++p)
    for (int c = 0; c < 3; ++c) {
      const int src = spec.nchannels >= 3 ? c : 0;  // grey (+alpha): replicate
      const float v = raw[p * spec.nchannels + src];
      if (!std::isfinite(v)) throw ImageError("image " + path.string() + " contains NaN or Inf");
      img.pixels[p * 3 + c] = v;
    }
  return img;
}

void write_image(const std::filesystem::path& path, const FloatImage& image) {
  if (image.pixels.size() != size_t(image.width) * image.height * image.channels || image.width <= 0)
    throw ImageError("write_image " + path.string() + ": pixel buffer does not match its size");
  std::vector<uint8_t> bytes(image.pixels.size());
  for (size_t i = 0; i < bytes.size(); ++i) {
    const float v = std::isfinite(image.pixels[i]) ? std::clamp(image.pixels[i], 0.0f, 1.0f) : 0.0f;
    bytes[i] = static_cast<uint8_t>(std::lround(v * 255.0f));
  }
  OIIO::ImageSpec spec(image.width, image.height, image.channels, OIIO::TypeDesc::UINT8);
  // Our RGBA is straight (unassociated) alpha, as PNG stores it: without this OIIO would
  // treat it as premultiplied and divide the colors by alpha once more.
  spec.attribute("oiio:UnassociatedAlpha", 1);
  write_encoded_image(path, spec, OIIO::TypeDesc::UINT8, bytes.data());
}

}  // namespace desplat
