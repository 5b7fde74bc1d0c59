// Whether a JPEG file's compressed data runs to its end marker. libjpeg (and so OpenImageIO)
// decodes a truncated JPEG without an error, filling the missing rows with grey: a photo cut
// short by a failed copy would be trained on as a grey image. Used by the image reader and by
// the photo scan before structure from motion.
#pragma once

#include <filesystem>

namespace desplat {

// True when the file at `path` holds an end-of-image marker (FF D9) after its first
// start-of-scan marker (FF DA). In the entropy-coded data a byte FF is always followed by
// 00 or a restart marker (D0–D7), so FF D9 cannot occur there by chance; markers before the
// first scan (EXIF thumbnails, tables) are skipped by their lengths. Data after the end
// marker (motion photos, vendor trailers) is allowed. Throws std::runtime_error when the
// file cannot be read.
bool jpeg_reaches_end_marker(const std::filesystem::path& path);

}  // namespace desplat
