// Image files through OpenImageIO. Pixels are float, row-major [H, W, C], values in
// [0, 1] (8/16-bit files are scaled by their maximum; float files are read as stored).
#pragma once

#include <filesystem>
#include <stdexcept>
#include <vector>

#include "desplat/core/image.hpp"

namespace desplat {

struct ImageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Reads any format OpenImageIO knows as float RGB (grey is replicated, alpha dropped).
// Throws ImageError naming the file when it cannot be read.
FloatImage read_image_rgb(const std::filesystem::path& path);

// Writes an 8-bit PNG (or JPEG, by extension), clamping to [0, 1] and rounding. The file is
// encoded in memory and replaced atomically with every write checked (atomic_file.hpp): on a
// full disk the old file, or none, stays. Throws ImageError naming the file on failure.
void write_image(const std::filesystem::path& path, const FloatImage& image);

}  // namespace desplat
