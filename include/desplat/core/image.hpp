// In-memory images: float pixels, row-major [H, W, C], values nominally in [0, 1].
// Pixel (i, j) has its center at (i + 0.5, j + 0.5) (docs/METHOD.md §1). Reading and writing
// image files is io/image_io.hpp; training and rendering need only this type.
#pragma once

#include <string>
#include <vector>

namespace desplat {

// Owns its pixels. C is 1 (masks, alphas) or 3 (RGB).
struct FloatImage {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  // [H, W, C]
};

// "WxH", the way error messages print an image size.
inline std::string size_text(int width, int height) { return std::to_string(width) + "x" + std::to_string(height); }

}  // namespace desplat
