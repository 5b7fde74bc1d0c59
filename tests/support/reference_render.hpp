// Brute-force reference renderer: every Gaussian against every pixel, one global
// depth sort, no tiles, no bounding boxes, no early exits beyond the blending rule
// itself. Templated over the scalar so it runs in double (values) and in ceres::Jet
// (exact derivatives). It shares only the per-stage formulas (stage_math.hpp), whose
// own derivatives are tested separately.
#pragma once

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/param_groups.hpp"
#include "raster/stage_math.hpp"

namespace desplat::test {

template <typename T>
struct RefGaussians {
  std::vector<T> means, log_scales, quats, opacity_logits, colors;
  std::vector<T> features;  // the appearance features; the render never reads them
  ColorMode color_mode = ColorMode::SphericalHarmonics;
  int sh_degree = 0;
  size_t size() const { return opacity_logits.size(); }
  // The array of a parameter group (the table's order, desplat/train/param_groups.hpp).
  std::vector<T>& array(ParamGroup g) {
    std::vector<T>* arrays[kParamGroups] = {&means, &log_scales, &quats, &opacity_logits, &colors, &features};
    static_assert(kParamGroups == 6, "a new parameter group needs its array here");
    return *arrays[static_cast<int>(g)];
  }
};

template <typename T>
RefGaussians<T> to_ref(const GaussianSet& g) {
  auto conv = [](const std::vector<float>& v) { return std::vector<T>(v.begin(), v.end()); };
  RefGaussians<T> r;
  r.means = conv(g.means);
  r.log_scales = conv(g.log_scales);
  r.quats = conv(g.quats);
  r.opacity_logits = conv(g.opacity_logits);
  r.colors = conv(g.colors);
  r.color_mode = g.color_mode;
  r.sh_degree = g.sh_degree;
  return r;
}

template <typename T>
struct RefImage {
  std::vector<T> color, alpha, depth;  // [H,W,3], [H,W], [H,W]
  // 1 where some blending decision (α ≥ 1/255, T·(1 − α) ≤ 1e-4) lies within a
  // relative 1e-4 of its threshold: float32 rounding may legitimately decide it the
  // other way, so such pixels cannot be compared tightly.
  std::vector<uint8_t> near_threshold;  // [H,W]
};

template <typename T>
double value_of(const T& v) {
  if constexpr (std::is_arithmetic_v<T>)
    return static_cast<double>(v);
  else
    return v.a;
}

template <typename T>
RefImage<T> reference_render(const RefGaussians<T>& g, const Camera& cam, const RasterSettings& s) {
  using namespace raster;
  const int n = static_cast<int>(g.size());
  const int degree = s.active_sh_degree < 0 ? g.sh_degree : s.active_sh_degree;
  const bool sh_mode = g.color_mode == ColorMode::SphericalHarmonics;
  const int stride = sh_mode ? 3 * (g.sh_degree + 1) * (g.sh_degree + 1) : 3;
  const PinholeIntrinsics K{cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height};
  Mat3<T> W;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) W(r, c) = T(cam.R_cw[3 * r + c]);
  const Vec3<T> t(T(cam.t_cw[0]), T(cam.t_cw[1]), T(cam.t_cw[2]));
  const Vec3<T> center = -W.transpose() * t;

  struct Splat {
    Vec2<T> mean2d;
    Vec3<T> conic, rgb;
    T opacity, depth;
    int id;
  };
  std::vector<Splat> splats;
  for (int i = 0; i < n; ++i) {
    const Vec3<T> mean(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
    const Vec3<T> p = W * mean + t;
    if (!(p[2] > T(s.near_plane) && p[2] < T(s.far_plane))) continue;
    const Mat3<T> V = W * covariance_3d<T>(&g.log_scales[3 * i], &g.quats[4 * i]) * W.transpose();
    const Projection<T> proj = project_ewa<T>(p, V, K, s.eps2d);
    T det;
    const Vec3<T> conic = conic_from_cov2d<T>(proj.cov2d, &det);
    if (!(det > T(0))) continue;
    Vec3<T> rgb = evaluate_color<T>(sh_mode, degree, &g.colors[stride * i], mean, center);
    for (int ch = 0; ch < 3; ++ch) {
      if (rgb[ch] < T(0)) rgb[ch] = T(0);
      if (!sh_mode && rgb[ch] > T(1)) rgb[ch] = T(1);
    }
    splats.push_back({proj.mean2d, conic, rgb, sigmoid<T>(g.opacity_logits[i]), p[2], i});
  }
  // Sort indices, not the structs: Jet members need an alignment that
  // std::stable_sort's temporary buffer does not provide.
  std::vector<int> order(splats.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return value_of(splats[a].depth) < value_of(splats[b].depth); });

  RefImage<T> img;
  const size_t pixels = size_t(cam.width) * cam.height;
  img.color.assign(3 * pixels, T(0));
  img.alpha.assign(pixels, T(0));
  img.depth.assign(pixels, T(0));
  img.near_threshold.assign(pixels, 0);
  auto near = [](double v, double threshold) { return std::abs(v - threshold) < 1e-4 * threshold; };
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const size_t pix = size_t(y) * cam.width + x;
      T trans(1);
      for (int idx : order) {
        const Splat& sp = splats[idx];
        const T dx = sp.mean2d[0] - T(x + 0.5), dy = sp.mean2d[1] - T(y + 0.5);
        const T sigma = gaussian_sigma<T>(sp.conic[0], sp.conic[1], sp.conic[2], dx, dy);
        if (sigma < T(0)) continue;
        using std::exp;
        const T alpha = clamp_alpha<T>(sp.opacity * exp(-sigma));
        const T next = trans * (T(1) - alpha);
        if (near(value_of(alpha), kAlphaMin) || near(value_of(next), kTransmittanceMin)) img.near_threshold[pix] = 1;
        if (alpha < T(kAlphaMin)) continue;
        if (next <= T(kTransmittanceMin)) break;
        for (int ch = 0; ch < 3; ++ch) img.color[3 * pix + ch] += sp.rgb[ch] * alpha * trans;
        img.depth[pix] += sp.depth * alpha * trans;
        trans = next;
      }
      img.alpha[pix] = T(1) - trans;
    }
  return img;
}

}  // namespace desplat::test
