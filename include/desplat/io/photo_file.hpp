// Photo files read and written back as they are stored, for tools that edit a capture's photos
// in place of the photographer (desplat_occlude): every channel, alpha unassociated, the file's
// format and metadata (EXIF orientation and the like) kept for the write-back. Training reads
// photos through image_io.hpp instead (RGB only).
//
// Pixels are float [H, W, C] in [0, 1], C as stored (1–4). Ownership: plain values; the
// metadata is shared, immutable and opaque (no OpenImageIO type in this header).
// Errors throw ImageError naming the file.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "desplat/core/image.hpp"
#include "desplat/io/image_io.hpp"

namespace desplat {

struct PhotoMetadata;  // the file's header, defined in photo_file.cpp

struct PhotoFile {
  FloatImage image;    // channels as stored
  std::string format;  // e.g. "jpeg", "png"
  std::shared_ptr<const PhotoMetadata> metadata;
};

PhotoFile read_photo_file(const std::filesystem::path& path);

// Width and height from the file's header, without decoding it.
std::array<int, 2> read_image_size(const std::filesystem::path& path);

// Writes `photo.image` with the metadata and bit depth it was read with (the same format when
// `path` has the same extension); JPEG at quality 95 with 4:4:4 chroma, so that pixels left
// alone change only by re-encoding noise.
void write_photo_file(const std::filesystem::path& path, const PhotoFile& photo);

// An 8-bit single-channel image (e.g. a mask, 255 = set), `pixels` row-major [H, W].
void write_mask_u8(const std::filesystem::path& path, int width, int height, const uint8_t* pixels);

}  // namespace desplat
