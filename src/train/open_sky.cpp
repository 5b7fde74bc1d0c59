#include "desplat/train/open_sky.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "desplat/core/statistics.hpp"

namespace desplat {

double OpenSkyCells::share(int width, int height) const {
  if (cell <= 0 || width <= 0 || height <= 0) return 0.0;
  int64_t pixels = 0;  // the partial cells at the right and bottom edges count for what they cover
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < columns; ++x)
      if (open[size_t(y) * columns + x])
        pixels +=
            int64_t(std::max(0, std::min(cell, width - x * cell))) * std::max(0, std::min(cell, height - y * cell));
  return double(pixels) / (double(width) * height);
}

OpenSkyCells open_sky_cells(const Camera& camera, const ByteImage& image, const std::vector<long long>& samples,
                            int columns, float smooth_ratio) {
  if (columns < 1) throw std::invalid_argument("open_sky_cells: columns must be ≥ 1");
  if (image.width != camera.width || image.height != camera.height || image.channels != 3)
    throw std::invalid_argument("open_sky_cells: the image does not match its camera");
  OpenSkyCells sky;
  sky.cell = std::max(1, (camera.width + columns - 1) / columns);
  sky.columns = (camera.width + sky.cell - 1) / sky.cell;
  sky.rows = (camera.height + sky.cell - 1) / sky.cell;
  const int cw = sky.columns, ch = sky.rows, cell = sky.cell;
  std::vector<uint8_t> occupied(size_t(cw) * ch, 0);
  sky.open.assign(size_t(cw) * ch, 0);
  const long long pixels = (long long)camera.width * camera.height;
  for (const long long p : samples)
    if (p >= 0 && p < pixels) occupied[size_t((p / camera.width) / cell) * cw + size_t((p % camera.width) / cell)] = 1;
  // Texture per cell: the mean |Laplacian| of the luminance's kBlock × kBlock means.
  constexpr int kBlock = 4;
  auto value = [&](size_t i) { return byte_to_float(image.pixels[i]); };
  const int bw = camera.width / kBlock, bh = camera.height / kBlock;
  std::vector<float> block(size_t(std::max(bw, 0)) * std::max(bh, 0), 0.0f);
  for (int y = 0; y < bh * kBlock; ++y)
    for (int x = 0; x < bw * kBlock; ++x) {
      const size_t p = 3 * (size_t(y) * camera.width + x);
      block[size_t(y / kBlock) * bw + x / kBlock] +=
          (0.299f * value(p) + 0.587f * value(p + 1) + 0.114f * value(p + 2)) / float(kBlock * kBlock);
    }
  std::vector<double> texture(size_t(cw) * ch, 0.0), count(size_t(cw) * ch, 0.0);
  for (int y = 1; y + 1 < bh; ++y)
    for (int x = 1; x + 1 < bw; ++x) {
      const float* b = &block[size_t(y) * bw + x];
      const float lap = std::abs(b[-1] + b[1] - 2 * b[0]) + std::abs(b[-bw] + b[bw] - 2 * b[0]);
      const size_t c = size_t((y * kBlock + kBlock / 2) / cell) * cw + size_t((x * kBlock + kBlock / 2) / cell);
      texture[c] += lap, count[c] += 1;
    }
  std::vector<double> surface;
  for (size_t c = 0; c < texture.size(); ++c) {
    texture[c] /= std::max(1.0, count[c]);
    if (occupied[c]) surface.push_back(texture[c]);
  }
  const double smooth = smooth_ratio * (surface.empty() ? 0.0 : median(surface));
  auto sky_like = [&](size_t c) { return !occupied[c] && texture[c] <= smooth; };
  std::vector<int> stack;
  for (int x = 0; x < cw; ++x)
    if (sky_like(size_t(x))) sky.open[size_t(x)] = 1, stack.push_back(x);
  while (!stack.empty()) {  // flood fill from the top row through sky-like cells (4-neighbours)
    const int c = stack.back();
    stack.pop_back();
    const int x = c % cw, y = c / cw;
    for (const auto& [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      const int nx = x + dx, ny = y + dy;
      if (nx < 0 || ny < 0 || nx >= cw || ny >= ch) continue;
      const int n = ny * cw + nx;
      if (sky_like(size_t(n)) && !sky.open[size_t(n)]) sky.open[size_t(n)] = 1, stack.push_back(n);
    }
  }
  return sky;
}

}  // namespace desplat
