// Checked image writing for the io layer's writers (renders, the image cache, photos, masks).
// Private to the io layer.
#pragma once

#include <OpenImageIO/imageio.h>

#include <filesystem>

namespace desplat {

// Encodes `pixels` (laid out as `spec`, element type `type`) in the format `path`'s extension
// names, in memory, then replaces `path` through write_file_atomically: every write, the
// flush, the fsync and the rename are checked, so a full disk or a vanished folder is an
// ImageError naming `path` (never a 0-byte or partial file that claims success). Creates
// missing parent folders. `what` names the kind of file in the message ("image", "mask").
void write_encoded_image(const std::filesystem::path& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                         const void* pixels, const char* what = "image");

}  // namespace desplat
