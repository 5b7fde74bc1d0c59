// Line plots as images, for desplat_bench's reports (accuracy against time, against clutter).
//
// Frames and units: data coordinates are whatever the caller plots (seconds, dB, ratios);
// the returned image is [H, W, 3] RGB in [0, 1], y up on the plot (larger values higher).
//
// Ownership and threads: plain values, no shared state.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "desplat/core/image.hpp"

namespace desplat {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;  // equal sizes; points are joined in the given order
  int color = -1;            // palette index; -1: the series' position in the list
};

struct PlotSpec {
  std::string title, x_label, y_label;
  int width = 960, height = 600;  // pixels
};

// Where data coordinates land in the image: the axes span [x_min, x_max] × [y_min, y_max]
// (the data range with a 5 % margin) inside the pixel box [left, right] × [top, bottom].
struct PlotFrame {
  double x_min = 0, x_max = 1, y_min = 0, y_max = 1;
  int left = 0, right = 0, top = 0, bottom = 0;
  double pixel_x(double x) const { return left + (x - x_min) / (x_max - x_min) * (right - left); }
  double pixel_y(double y) const { return bottom - (y - y_min) / (y_max - y_min) * (bottom - top); }
};

// The frame draw_line_plot uses for these series (non-finite points are ignored).
PlotFrame plot_frame(const PlotSpec& spec, const std::vector<PlotSeries>& series);

// White background, axes with ticks and labels, one colored polyline with markers per series
// (palette color `color`, or i for series i), a legend. Throws std::invalid_argument when a series' x and y
// sizes differ or there is no finite point at all.
FloatImage draw_line_plot(const PlotSpec& spec, const std::vector<PlotSeries>& series);

// Tick values for an axis spanning [lo, hi]: the multiples of the smallest step of the
// form 1, 2 or 5 × 10^k that gives at most 8 of them inside the span (at least 2 whenever
// hi > lo), so labels read 0, 100, 200 rather than -14.75, 120.5.
std::vector<double> nice_ticks(double lo, double hi);

// The RGB color in [0, 1] of series i (a 10-color palette, repeating).
std::array<float, 3> plot_color(size_t i);

}  // namespace desplat
