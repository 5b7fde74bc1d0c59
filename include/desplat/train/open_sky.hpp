// Where a photo shows open sky, judged from the photo and its SfM points alone (docs/METHOD.md
// §10): the grid cells that hold no SfM point, are smooth, and connect to the frame's top edge
// through such cells. `--effects auto` turns the background model on when they cover enough of
// the median view (effects.hpp).
#pragma once

#include <cstdint>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/image.hpp"

namespace desplat {

// Square cells of `cell` full-resolution pixels, `columns` × `rows` of them (the last column and
// row may be partial); open[row · columns + column] = 1 for an open-sky cell.
struct OpenSkyCells {
  int cell = 0, columns = 0, rows = 0;
  std::vector<uint8_t> open;

  // The share of a width × height frame (the photo's) that open cells cover, in pixels.
  double share(int width, int height) const;
};

// `samples`: pixel indices (y · width + x) of the SfM points the photo observes. A cell is
// smooth when the mean |Laplacian| of the luminance's 4 × 4-pixel means in it is at most
// smooth_ratio × the median of the cells that hold samples: the block means average sensor
// noise away, the Laplacian ignores a sky's smooth gradient, and the ratio is relative to this
// photo's own textured surfaces, so no absolute noise level is assumed. Open but textured cells
// are surfaces SfM did not match (a repetitive wallpaper), not sky. `columns` ≥ 1 cells across.
OpenSkyCells open_sky_cells(const Camera& camera, const ByteImage& image, const std::vector<long long>& samples,
                            int columns, float smooth_ratio);

}  // namespace desplat
