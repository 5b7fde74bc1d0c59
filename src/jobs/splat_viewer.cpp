// The report's WebGL2 splat viewer (see splat_viewer.hpp): C++ packs the Gaussians, the page's
// script sorts and draws them.
#include "jobs/splat_viewer.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <vector>

#include "desplat/core/spherical_harmonics.hpp"
#include "jobs/base64.hpp"
#include "jobs/report_assets.hpp"

namespace desplat {
namespace {

constexpr int kFloatsPerSplat = 13;  // mean (3), covariance xx xy xz yy yz zz (6), rgba (4)

float sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// Mean, 3D covariance R·S²·Rᵀ and straight RGBA (SH DC colour, sigmoid opacity) per Gaussian.
std::vector<float> pack(const GaussianSet& g, const std::vector<size_t>& chosen) {
  const int k = sh_coeff_count(g.sh_degree);
  std::vector<float> out;
  out.reserve(chosen.size() * kFloatsPerSplat);
  for (size_t i : chosen) {
    double w = g.quats[4 * i], x = g.quats[4 * i + 1], y = g.quats[4 * i + 2], z = g.quats[4 * i + 3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    w /= n, x /= n, y /= n, z /= n;
    const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    double s2[3];
    for (int a = 0; a < 3; ++a) s2[a] = std::exp(2.0 * g.log_scales[3 * i + a]);
    auto cov = [&](int r, int c) {
      double v = 0;
      for (int a = 0; a < 3; ++a) v += R[r][a] * s2[a] * R[c][a];
      return float(v);
    };
    for (int a = 0; a < 3; ++a) out.push_back(g.means[3 * i + a]);
    for (auto [r, c] : {std::pair{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}}) out.push_back(cov(r, c));
    for (int c = 0; c < 3; ++c)
      out.push_back(std::clamp(0.5f + float(kShBand0) * g.colors[size_t(i) * k * 3 + c], 0.0f, 1.0f));
    out.push_back(sigmoid(g.opacity_logits[i]));
  }
  return out;
}

// The starting camera when the scene's cameras are not available: looking along +z at the
// centroid from 2.5 times the spread.
ViewerCamera framing(const GaussianSet& g) {
  ViewerCamera c;
  double center[3] = {0, 0, 0}, spread = 0;
  const size_t n = g.size();
  for (size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) center[a] += g.means[3 * i + a] / double(n);
  for (size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) spread += std::pow(g.means[3 * i + a] - center[a], 2) / double(n);
  const double d = 2.5 * std::sqrt(spread) + 1e-6;
  c.t = {-center[0], -center[1], -center[2] + d};
  return c;
}


}  // namespace

std::string splat_viewer_section(const GaussianSet& g, const std::optional<ViewerCamera>& start,
                                 const std::array<float, 3>& background, size_t max_gaussians) {
  std::vector<size_t> chosen(g.size());
  std::iota(chosen.begin(), chosen.end(), size_t(0));
  if (chosen.size() > max_gaussians) {  // the most visible: opacity × largest extent
    auto weight = [&](size_t i) {
      const float s = std::max({g.log_scales[3 * i], g.log_scales[3 * i + 1], g.log_scales[3 * i + 2]});
      return sigmoid(g.opacity_logits[i]) * std::exp(s);
    };
    std::nth_element(chosen.begin(), chosen.begin() + std::ptrdiff_t(max_gaussians), chosen.end(),
                     [&](size_t a, size_t b) { return weight(a) > weight(b); });
    chosen.resize(max_gaussians);
    std::sort(chosen.begin(), chosen.end());
  }
  const std::vector<float> packed = pack(g, chosen);
  const ViewerCamera c = start ? *start : framing(g);
  char config[1024];
  std::snprintf(config, sizeof config,
                "{\"R\":[%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g],\"t\":[%.9g,%.9g,%.9g],\"fx\":%.9g,\"fy\":%.9g,"
                "\"cx\":%.9g,\"cy\":%.9g,\"width\":%d,\"height\":%d,\"background\":[%.6g,%.6g,%.6g]}",
                c.R[0], c.R[1], c.R[2], c.R[3], c.R[4], c.R[5], c.R[6], c.R[7], c.R[8], c.t[0], c.t[1], c.t[2], c.fx,
                c.fy, c.cx, c.cy, c.width, c.height, background[0], background[1], background[2]);
  // The canvas keeps the starting camera's aspect, 960 px wide.
  const int w = 960, h = int(std::lround(double(c.height) * w / c.width));
  std::string s = "<h2>The model in 3D (static Gaussians, point_cloud.ply)</h2>\n";
  if (chosen.size() < g.size())
    s += "<p>Showing the " + std::to_string(chosen.size()) + " most visible of " + std::to_string(g.size()) +
         " Gaussians.</p>\n";
  s += "<canvas id=\"splat-canvas\" width=\"" + std::to_string(w) + "\" height=\"" + std::to_string(h) +
       "\" style=\"max-width:100%;cursor:grab;touch-action:none\"></canvas>\n<p id=\"splat-status\">Loading…</p>\n";
  s += "<script type=\"application/json\" id=\"splat-config\">" + std::string(config) + "</script>\n";
  s += "<script type=\"application/octet-stream\" id=\"splat-data\">" +
       base64(packed.data(), packed.size() * sizeof(float)) + "</script>\n";
  s += "<script>\n" + std::string(assets::splat_viewer_js) + "</script>\n";
  return s;
}

}  // namespace desplat
