// In-memory images, row-major [H, W, C], pixel (i, j) centered at (i + 0.5, j + 0.5)
// (docs/METHOD.md §1). Reading and writing image files is io/image_io.hpp; training and
// rendering need only these types.
//   FloatImage: what the kernels, losses and metrics compute with; values nominally in [0, 1].
//   ByteImage:  how training holds its photos, 8 bits per channel (a quarter of the memory);
//               byte b stands for b / 255. Converted to float for the view a step uses.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace desplat {

// Owns its pixels. C is 1 (masks, alphas) or 3 (RGB).
struct FloatImage {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  // [H, W, C]
};

// Owns its pixels. C is 1 or 3.
struct ByteImage {
  int width = 0, height = 0, channels = 0;
  std::vector<uint8_t> pixels;  // [H, W, C], value = byte / 255
};

// The float value of a byte: one table, so every conversion of a photo gives the same bits.
float byte_to_float(uint8_t b);

// Rounds each value, clamped to [0, 1], to the nearest byte (NaN becomes 0). A float that
// came from a byte (b / 255) gives that byte back.
ByteImage to_bytes(const FloatImage& image);
FloatImage to_float(const ByteImage& image);
// The same into a buffer the caller keeps (out.size() must equal image.pixels.size()).
void to_float(const ByteImage& image, std::span<float> out);

// The mean of each factor × factor block, rounded to the nearest byte (the last partial row
// and column are dropped; the size is ⌊W/factor⌋ × ⌊H/factor⌋, at least 1 × 1). Computed in
// integers from the full image, so it does not depend on how the block sum is ordered.
ByteImage downscale_bytes(const ByteImage& image, int factor);

// "WxH", the way error messages print an image size.
inline std::string size_text(int width, int height) { return std::to_string(width) + "x" + std::to_string(height); }

}  // namespace desplat
