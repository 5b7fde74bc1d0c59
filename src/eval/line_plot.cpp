#include "desplat/eval/line_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace desplat {
namespace {

// Tableau-like palette: distinguishable, and readable on white.
constexpr unsigned char kPalette[10][3] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44},  {214, 39, 40},
                                           {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {127, 127, 127},
                                           {188, 189, 34}, {23, 190, 207}};

cv::Scalar bgr(size_t i) {
  const unsigned char* c = kPalette[i % 10];
  return cv::Scalar(c[2], c[1], c[0]);
}

std::string tick_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", std::abs(v) < 1e-12 ? 0.0 : v);
  return buf;
}

}  // namespace

std::array<float, 3> plot_color(size_t i) {
  const unsigned char* c = kPalette[i % 10];
  return {c[0] / 255.0f, c[1] / 255.0f, c[2] / 255.0f};
}

std::vector<double> nice_ticks(double lo, double hi) {
  if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi)) return {};
  constexpr double kMaxTicks = 8;
  const double magnitude = std::pow(10.0, std::floor(std::log10((hi - lo) / kMaxTicks)));
  double step = 10 * magnitude;
  for (double m : {1.0, 2.0, 5.0})
    if ((hi - lo) / (m * magnitude) < kMaxTicks) {
      step = m * magnitude;
      break;
    }
  std::vector<double> ticks;
  // k · step rather than repeated addition: no accumulated rounding in the labels.
  for (double k = std::ceil(lo / step); k * step <= hi; ++k) ticks.push_back(k * step);
  return ticks;
}

PlotFrame plot_frame(const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const PlotSeries& s : series) {
    if (s.x.size() != s.y.size())
      throw std::invalid_argument("plot series '" + s.label + "' has " + std::to_string(s.x.size()) + " x but " +
                                  std::to_string(s.y.size()) + " y values");
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i]), y1 = std::max(y1, s.y[i]);
    }
  }
  if (!std::isfinite(x0)) throw std::invalid_argument("plot '" + spec.title + "' has no finite point");
  // A single value still gets a visible range.
  if (x1 - x0 < 1e-12) x0 -= 0.5, x1 += 0.5;
  if (y1 - y0 < 1e-12) y0 -= 0.5, y1 += 0.5;
  const double mx = 0.05 * (x1 - x0), my = 0.05 * (y1 - y0);
  PlotFrame f;
  f.x_min = x0 - mx, f.x_max = x1 + mx, f.y_min = y0 - my, f.y_max = y1 + my;
  // The legend sits right of the axes: leave room for the longest label.
  int legend = 0;
  for (const PlotSeries& s : series) {
    int baseline = 0;
    legend = std::max(legend, cv::getTextSize(s.label, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &baseline).width);
  }
  f.left = 90, f.right = spec.width - std::clamp(legend + 70, 150, spec.width / 2), f.top = 62;
  f.bottom = spec.height - 70;
  return f;
}

FloatImage draw_line_plot(const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  const PlotFrame f = plot_frame(spec, series);
  cv::Mat img(spec.height, spec.width, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar ink(40, 40, 40), grid(225, 225, 225);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  for (double xv : nice_ticks(f.x_min, f.x_max)) {
    const int px = int(std::lround(f.pixel_x(xv)));
    cv::line(img, {px, f.top}, {px, f.bottom}, grid, 1);
    int baseline = 0;
    const std::string label = tick_text(xv);
    const int half = cv::getTextSize(label, font, 0.45, 1, &baseline).width / 2;  // centred under its line
    cv::putText(img, label, {px - half, f.bottom + 20}, font, 0.45, ink, 1, cv::LINE_AA);
  }
  for (double yv : nice_ticks(f.y_min, f.y_max)) {
    const int py = int(std::lround(f.pixel_y(yv)));
    cv::line(img, {f.left, py}, {f.right, py}, grid, 1);
    cv::putText(img, tick_text(yv), {8, py + 5}, font, 0.45, ink, 1, cv::LINE_AA);
  }
  cv::rectangle(img, {f.left, f.top}, {f.right, f.bottom}, ink, 1);
  cv::putText(img, spec.title, {8, 24}, font, 0.6, ink, 1, cv::LINE_AA);
  cv::putText(img, spec.x_label, {(f.left + f.right) / 2 - 60, spec.height - 25}, font, 0.5, ink, 1, cv::LINE_AA);
  cv::putText(img, spec.y_label, {8, f.top - 14}, font, 0.5, ink, 1, cv::LINE_AA);

  for (size_t s = 0; s < series.size(); ++s) {
    const cv::Scalar color = bgr(series[s].color >= 0 ? size_t(series[s].color) : s);
    std::vector<cv::Point> pts;
    for (size_t i = 0; i < series[s].x.size(); ++i)
      if (std::isfinite(series[s].x[i]) && std::isfinite(series[s].y[i]))
        pts.emplace_back(int(std::lround(f.pixel_x(series[s].x[i]))), int(std::lround(f.pixel_y(series[s].y[i]))));
    if (pts.size() > 1) cv::polylines(img, pts, false, color, 2, cv::LINE_AA);
    for (const cv::Point& p : pts) cv::circle(img, p, 4, color, cv::FILLED, cv::LINE_AA);
    const int ly = f.top + 10 + 22 * int(s);
    cv::line(img, {f.right + 15, ly}, {f.right + 45, ly}, color, 3);
    cv::putText(img, series[s].label, {f.right + 52, ly + 5}, font, 0.45, ink, 1, cv::LINE_AA);
  }

  FloatImage out{spec.width, spec.height, 3, std::vector<float>(size_t(spec.width) * spec.height * 3)};
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) out.pixels[(size_t(y) * spec.width + x) * 3 + c] = p[2 - c] / 255.0f;
    }
  return out;
}

}  // namespace desplat
