// The 8-bit image conversions of core/image.hpp.
#include "desplat/core/image.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace desplat {

namespace {

const std::array<float, 256>& byte_values() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    // b · (1/255) in float, as OpenImageIO converts 8-bit files: a photo held in bytes gives
    // the bits its float reading gave.
    for (int b = 0; b < 256; ++b) t[b] = float(b) * (1.0f / 255.0f);
    return t;
  }();
  return table;
}

}  // namespace

float byte_to_float(uint8_t b) { return byte_values()[b]; }

ByteImage to_bytes(const FloatImage& image) {
  ByteImage out{image.width, image.height, image.channels, std::vector<uint8_t>(image.pixels.size())};
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const float v = image.pixels[i];
    out.pixels[i] = std::isnan(v) ? uint8_t(0) : uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
  }
  return out;
}

void to_float(const ByteImage& image, std::span<float> out) {
  if (out.size() != image.pixels.size())
    throw std::invalid_argument("to_float: the buffer holds " + std::to_string(out.size()) + " values for " +
                                std::to_string(image.pixels.size()));
  const std::array<float, 256>& table = byte_values();
  for (size_t i = 0; i < out.size(); ++i) out[i] = table[image.pixels[i]];
}

FloatImage to_float(const ByteImage& image) {
  FloatImage out{image.width, image.height, image.channels, std::vector<float>(image.pixels.size())};
  to_float(image, out.pixels);
  return out;
}

ByteImage downscale_bytes(const ByteImage& image, int factor) {
  if (factor < 1) throw std::invalid_argument("downscale_bytes: factor " + std::to_string(factor) + " < 1");
  const int C = image.channels;
  ByteImage out{std::max(1, image.width / factor), std::max(1, image.height / factor), C, {}};
  out.pixels.resize(size_t(out.width) * out.height * C);
  const int bw = std::min(factor, image.width), bh = std::min(factor, image.height);  // a 1×1 result of a smaller image
  const uint32_t count = uint32_t(bw) * uint32_t(bh);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < C; ++c) {
        uint32_t sum = 0;
        for (int dy = 0; dy < bh; ++dy)
          for (int dx = 0; dx < bw; ++dx)
            sum += image.pixels[(size_t(y * factor + dy) * image.width + (x * factor + dx)) * C + c];
        out.pixels[(size_t(y) * out.width + x) * C + c] = uint8_t((sum + count / 2) / count);  // round half up
      }
  return out;
}

}  // namespace desplat
