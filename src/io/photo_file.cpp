// Photo files as stored, through OpenImageIO (see photo_file.hpp).
#include "desplat/io/photo_file.hpp"

#include <OpenImageIO/imageio.h>

#include "desplat/io/jpeg_end.hpp"
#include "io/image_read_helpers.hpp"
#include "io/image_write_helpers.hpp"

namespace desplat {

struct PhotoMetadata {
  OIIO::ImageSpec spec;
};

PhotoFile read_photo_file(const std::filesystem::path& path) {
  const OIIO::ImageSpec config = unassociated_alpha();
  auto in = OIIO::ImageInput::open(path.string(), &config);
  if (!in) throw ImageError(path.string() + ": cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  PhotoFile p;
  p.format = in->format_name();
  p.metadata = std::make_shared<const PhotoMetadata>(PhotoMetadata{spec});
  p.image = FloatImage{spec.width, spec.height, spec.nchannels, {}};
  p.image.pixels.resize(size_t(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, p.image.pixels.data()))
    throw ImageError(path.string() + ": cannot decode the image: " + in->geterror());
  // A truncated JPEG decodes "successfully" with grey rows: an editing tool would write the
  // grey back as a valid photo.
  if (p.format == "jpeg" && !jpeg_reaches_end_marker(path))
    throw ImageError(path.string() +
                     ": the JPEG is truncated or damaged: its data ends before the end-of-image "
                     "marker (a decoder would fill the missing part with grey)");
  return p;
}

std::array<int, 2> read_image_size(const std::filesystem::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) throw ImageError(path.string() + ": cannot read the image: " + OIIO::geterror());
  return {in->spec().width, in->spec().height};
}

void write_photo_file(const std::filesystem::path& path, const PhotoFile& p) {
  if (!p.metadata) throw ImageError(path.string() + ": cannot write the image: it was not read with read_photo_file");
  OIIO::ImageSpec spec = p.metadata->spec;      // keeps the metadata (e.g. EXIF orientation)
  spec.attribute("oiio:UnassociatedAlpha", 1);  // write the pixels as read
  if (p.format == "jpeg") {
    spec.attribute("Compression", "jpeg:95");
    spec.attribute("jpeg:subsampling", "4:4:4");  // no chroma bleeding across edited edges
  }
  write_encoded_image(path, spec, OIIO::TypeDesc::FLOAT, p.image.pixels.data());
}

void write_mask_u8(const std::filesystem::path& path, int width, int height, const uint8_t* pixels) {
  write_encoded_image(path, OIIO::ImageSpec(width, height, 1, OIIO::TypeDesc::UINT8), OIIO::TypeDesc::UINT8, pixels,
                      "mask");
}

}  // namespace desplat
