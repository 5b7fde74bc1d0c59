// Plots for people: report.html's curves and desplat_bench's figures (docs/benchmarks/), drawn by
// gnuplot (Debian's gnuplot-nox, run as a subprocess) so they get real axes, ticks, legends
// and, as SVG, gnuplot's mouse script that shows the value under the pointer. One path for
// every plot the project draws.
//
// Frames and units: data coordinates are whatever the caller plots (steps, seconds, dB).
// Ownership and threads: plain values; concurrent calls need distinct scratch folders.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace desplat {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;  // equal sizes; joined in the given order; non-finite points are skipped
};

struct PlotSpec {
  std::string title, x_label, y_label;
  int width = 960, height = 600;  // pixels (SVG: the view box; it scales with the page)
  // Bars instead of lines: one bar per point of the first series, labelled bar_labels[i].
  bool bars = false;
  std::vector<std::string> bar_labels;
};

// A line plot's spec: title and axis labels, default size.
inline PlotSpec line_plot(std::string title, std::string x_label, std::string y_label) {
  PlotSpec spec;
  spec.title = std::move(title), spec.x_label = std::move(x_label), spec.y_label = std::move(y_label);
  return spec;
}

enum class PlotFormat { Svg, Png };

// gnuplot is missing or failed; what() says which and what to do.
class PlotError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Whether the gnuplot executable is on PATH.
bool plotting_available();

// The plot file's bytes (an SVG document or a PNG). `scratch` is a folder for gnuplot's script
// and output: created when missing, the two files removed afterwards. Throws
// std::invalid_argument when a series' x and y sizes differ, there is no finite point at all,
// or bars lack their labels; PlotError when gnuplot is missing or fails.
std::string draw_plot(const PlotSpec& spec, const std::vector<PlotSeries>& series, PlotFormat format,
                      const std::filesystem::path& scratch);

}  // namespace desplat
