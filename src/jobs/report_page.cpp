// The shared pieces of report.html pages (see report_page.hpp).
#include "jobs/report_page.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <thread>

#include "jobs/base64.hpp"
#include "jobs/report_assets.hpp"
#include "jobs/text_format.hpp"

namespace desplat::report {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument("cannot read " + path.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string escape_html(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string shown(double v, int digits) {
  if (!std::isfinite(v)) return v > 0 ? "inf" : "n/a";
  return fixed(v, digits);
}

double number(const json& j, const char* key, double fallback) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : fallback;
}

namespace {

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) return line.substr(colon + 2);
    }
  return "unknown CPU";
}

}  // namespace

std::string machine_text() {
  return cpu_model() + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

std::string row(const std::string& key, const std::string& value) {
  return "<tr><th>" + escape_html(key) + "</th><td>" + escape_html(value) + "</td></tr>\n";
}

std::string png_img(const fs::path& file, const std::string& alt) {
  return "<img alt=\"" + escape_html(alt) + "\" src=\"data:image/png;base64," + base64(read_bytes(file)) + "\">";
}

Plotter::~Plotter() {
  std::error_code ec;
  fs::remove_all(scratch_, ec);
}

std::string Plotter::svg(const PlotSpec& spec, const std::vector<Series>& series) {
  std::vector<PlotSeries> plot;
  for (const Series& s : series) {
    if (s.points.empty()) continue;
    PlotSeries p{s.label, {}, {}};
    for (const auto& [x, y] : s.points) p.x.push_back(x), p.y.push_back(y);
    plot.push_back(std::move(p));
  }
  if (plot.empty()) return "";
  PlotSpec sized = spec;
  sized.width = 620, sized.height = 340;
  try {
    std::string svg = draw_plot(sized, plot, PlotFormat::Svg, scratch_);
    ++drawn_;
    return svg;
  } catch (const std::exception& e) {  // PlotError, or no finite point
    note_ = e.what();
    return "";
  }
}

std::string plot_frame(const std::string& svg, const std::string& title) {
  if (svg.empty()) return "";
  std::string body = svg;
  if (body.rfind("<?xml", 0) == 0) body = body.substr(body.find("?>") + 2);
  return "<iframe class=\"plot\" title=\"" + escape_html(title) + "\" srcdoc=\"" +
         escape_html("<!DOCTYPE html><html><body style='margin:0'>" + body + "</body></html>") + "\"></iframe>\n";
}

std::string note_paragraph(const Plotter& plotter) {
  return plotter.note().empty() ? "" : "<p class=\"note\">" + escape_html(plotter.note()) + "</p>\n";
}

std::string page_start(const std::string& title) {
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + escape_html(title) +
         "</title><style>\n" + std::string(assets::report_css) + "</style><script>\n" +
         std::string(assets::report_self_check_js) + "</script></head><body>\n<h1>" + escape_html(title) + "</h1>\n";
}

}  // namespace desplat::report
