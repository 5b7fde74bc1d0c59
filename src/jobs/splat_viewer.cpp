// The report's WebGL2 splat viewer (see splat_viewer.hpp): C++ packs the Gaussians, the page's
// script sorts and draws them.
#include "jobs/splat_viewer.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
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
// The stored quaternion is (w, x, y, z) and need not be unit length (docs/METHOD.md §2).
std::vector<float> pack(const GaussianSet& g, const std::vector<size_t>& chosen) {
  const int k = sh_coeff_count(g.sh_degree);
  std::vector<float> out;
  out.reserve(chosen.size() * kFloatsPerSplat);
  for (size_t i : chosen) {
    const float* q = &g.quats[4 * i];
    const glm::dmat3 R = glm::mat3_cast(glm::normalize(glm::dquat(q[0], q[1], q[2], q[3])));
    glm::dmat3 S2(0.0);
    for (int a = 0; a < 3; ++a) S2[a][a] = std::exp(2.0 * g.log_scales[3 * i + a]);
    const glm::dmat3 cov = R * S2 * glm::transpose(R);  // symmetric; GLM indexes [column][row]
    for (int a = 0; a < 3; ++a) out.push_back(g.means[3 * i + a]);
    for (auto [r, c] : {std::pair{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}}) out.push_back(float(cov[c][r]));
    for (int c = 0; c < 3; ++c)
      out.push_back(std::clamp(0.5f + float(kShBand0) * g.colors[size_t(i) * k * 3 + c], 0.0f, 1.0f));
    out.push_back(sigmoid(g.opacity_logits[i]));
  }
  return out;
}

// The starting camera when the scene's cameras are not available: looking along +z at the
// centroid from 2.5 times the spread (the RMS distance to the centroid).
ViewerCamera framing(const GaussianSet& g) {
  const size_t n = g.size();
  auto mean_of = [&](size_t i) { return glm::dvec3(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]); };
  glm::dvec3 center(0.0);
  for (size_t i = 0; i < n; ++i) center += mean_of(i) / double(n);
  double spread = 0;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec3 d = mean_of(i) - center;
    spread += glm::dot(d, d) / double(n);
  }
  const double distance = 2.5 * std::sqrt(spread) + 1e-6;
  // R = identity and eye = center − distance·z, so t = −R·eye = distance·z − center.
  const glm::dvec3 t = glm::dvec3(0, 0, distance) - center;
  ViewerCamera c;
  c.t = {t.x, t.y, t.z};
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
