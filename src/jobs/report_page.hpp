// The pieces every report.html page is built from (the training report, training_report.cpp;
// the benchmark report, bench_report.cpp): escaping, numbers, tables, inlined images, gnuplot
// plots in frames of their own, and the page's head with its embedded style and script
// (src/jobs/report_assets/). Private to the jobs layer.
#pragma once

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "desplat/eval/plot.hpp"

namespace desplat::report {

// The file's bytes; std::invalid_argument naming it when it cannot be read.
std::string read_bytes(const std::filesystem::path& path);

// `s` safe inside HTML text and attribute values.
std::string escape_html(const std::string& s);

// `v` with `digits` decimals; "inf" for +∞ (a perfect PSNR), "n/a" for NaN or −∞ (a missing key).
std::string shown(double v, int digits);

// j[key] when it is a number, else `fallback`.
double number(const nlohmann::json& j, const char* key, double fallback = NAN);

// "<CPU model>, <n> hardware threads": the machine the page was written on.
std::string machine_text();

// One table row, both cells escaped.
std::string row(const std::string& key, const std::string& value);

// An <img> holding the PNG file inline (base64 data URL).
std::string png_img(const std::filesystem::path& file, const std::string& alt);

struct Series {
  std::string label;
  std::vector<std::pair<double, double>> points;  // (x, y)
};

// SVG plots for a page; a plot that cannot be drawn leaves a note instead of failing the run.
// Scratch files live in `scratch`, removed with the plotter.
class Plotter {
 public:
  explicit Plotter(std::filesystem::path scratch) : scratch_(std::move(scratch)) {}
  ~Plotter();
  Plotter(const Plotter&) = delete;
  Plotter& operator=(const Plotter&) = delete;

  // The SVG's text, or "" when there is nothing to plot or it could not be drawn (note()).
  std::string svg(const PlotSpec& spec, const std::vector<Series>& series);
  int drawn() const { return drawn_; }
  const std::string& note() const { return note_; }

 private:
  std::filesystem::path scratch_;
  std::string note_;
  int drawn_ = 0;
};

// An SVG in an iframe of its own (gnuplot's scripts use fixed element ids); "" for "".
std::string plot_frame(const std::string& svg, const std::string& title);

// The plotter's note as a paragraph; "" when every plot was drawn.
std::string note_paragraph(const Plotter& plotter);

// <!DOCTYPE html> through the <h1> title: the head carries the page's style and the self-check
// script the headless-browser test reads (data attributes on <body> once the page has loaded).
std::string page_start(const std::string& title);

}  // namespace desplat::report
