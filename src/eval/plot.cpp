// Plots through gnuplot (see include/desplat/eval/plot.hpp).
#include "desplat/eval/plot.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "desplat/io/atomic_file.hpp"
#include "desplat/sfm/subprocess.hpp"

namespace desplat {
namespace {

namespace fs = std::filesystem;

// A gnuplot single-quoted string: a quote is written twice; no other escapes apply.
std::string quoted(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\n' || c == '\r') continue;
    out += c;
    if (c == '\'') out += '\'';
  }
  return out + "'";
}

void check(const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  bool any = false;
  for (const PlotSeries& s : series) {
    if (s.x.size() != s.y.size())
      throw std::invalid_argument("plot '" + spec.title + "': series '" + s.label + "' has " +
                                  std::to_string(s.x.size()) + " x and " + std::to_string(s.y.size()) + " y values");
    for (size_t i = 0; i < s.x.size(); ++i) any |= std::isfinite(s.x[i]) && std::isfinite(s.y[i]);
  }
  if (!any) throw std::invalid_argument("plot '" + spec.title + "': no finite point to plot");
  if (spec.bars && (series.empty() || spec.bar_labels.size() != series[0].y.size()))
    throw std::invalid_argument("plot '" + spec.title + "': bars need one label per value");
  if (spec.width < 100 || spec.height < 100)
    throw std::invalid_argument("plot '" + spec.title + "': size must be at least 100x100 px");
}

std::string script(const PlotSpec& spec, const std::vector<PlotSeries>& series, PlotFormat format,
                   const fs::path& output) {
  std::ostringstream s;
  s.precision(10);
  const std::string size = std::to_string(spec.width) + "," + std::to_string(spec.height);
  if (format == PlotFormat::Svg)
    s << "set terminal svg size " << size << " dynamic mouse standalone noenhanced font 'sans,11'\n";
  else
    s << "set terminal pngcairo size " << size << " noenhanced font 'sans,11'\n";
  s << "set output " << quoted(output.string()) << "\n"
    << "set title " << quoted(spec.title) << "\nset xlabel " << quoted(spec.x_label) << "\nset ylabel "
    << quoted(spec.y_label) << "\nset grid\nset key box opaque bottom right\n";
  for (size_t k = 0; k < series.size(); ++k) {
    s << "$D" << k << " << EOD\n";
    for (size_t i = 0; i < series[k].x.size(); ++i) {
      if (!std::isfinite(series[k].x[i]) || !std::isfinite(series[k].y[i])) continue;
      if (spec.bars)
        s << quoted(spec.bar_labels[i]) << ' ' << series[k].y[i] << "\n";
      else
        s << series[k].x[i] << ' ' << series[k].y[i] << "\n";
    }
    s << "EOD\n";
  }
  if (spec.bars) {
    s << "set style fill solid 0.7\nset boxwidth 0.6\nset yrange [0:*]\nunset key\n"
      << "plot $D0 using 0:2:xtic(1) with boxes title " << quoted(series[0].label) << "\n";
    return s.str();
  }
  s << "plot ";
  for (size_t k = 0; k < series.size(); ++k)
    s << (k ? ", " : "") << "$D" << k << " using 1:2 with " << (series[k].x.size() < 12 ? "linespoints pt 7" : "lines")
      << " lw 2 title " << quoted(series[k].label);
  return s.str() + "\n";
}

}  // namespace

bool plotting_available() { return find_executable("gnuplot").has_value(); }

std::string draw_plot(const PlotSpec& spec, const std::vector<PlotSeries>& series, PlotFormat format,
                      const fs::path& scratch) {
  check(spec, series);
  const auto gnuplot = find_executable("gnuplot");
  if (!gnuplot) throw PlotError("gnuplot is not installed (scripts/install_deps.sh installs gnuplot-nox)");
  std::error_code ec;
  fs::create_directories(scratch, ec);
  const fs::path script_file = scratch / "plot.gp",
                 output = scratch / (format == PlotFormat::Svg ? "plot.svg" : "plot.png");
  fs::remove(output, ec);
  write_file_atomically(script_file, script(spec, series, format, output));
  std::string printed;
  const ProcessExit e = run_subprocess(
      {gnuplot->string(), script_file.string()}, [&](std::string_view c) { printed += c; }, 60);
  std::ifstream in(output, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  fs::remove(script_file, ec);
  fs::remove(output, ec);
  if (!e.ok() || bytes.str().empty())
    throw PlotError("gnuplot could not draw '" + spec.title + "'" + (printed.empty() ? "" : ": " + printed));
  return bytes.str();
}

}  // namespace desplat
