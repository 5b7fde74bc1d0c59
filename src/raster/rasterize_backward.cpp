// Backward pass. Each tile walks its list back to front and writes, per (tile,
// Gaussian) entry, the gradient with respect to that Gaussian's 2D quantities. Then
// each Gaussian sums its entries in a fixed order and chains through color, opacity,
// conic and projection to its 3D parameters. No atomics; results do not depend on the
// thread count or the schedule.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "raster/fast_exp.hpp"
#include "raster/stage_math.hpp"
#include "raster/tiles.hpp"

namespace desplat {
namespace {
using namespace raster;

// Per (tile, Gaussian) entry, the gradient with respect to the Gaussian's 2D
// quantities from that tile's pixels: kEntrySlots floats in this order.
enum EntrySlot { kR, kG, kB, kZ, kO, kA, kB2, kC, kMx, kMy, kAbsX, kAbsY, kEntrySlots };

void backward_tile(const TileGrid& grid, int tile, const RasterOutput& fw, const float* dC,
                   const float* dA, const float* dD, float* entry_grads) {
  constexpr int S = kTileSize;
  const int x0 = (tile % grid.tiles_x) * S, y0 = (tile / grid.tiles_x) * S;
  const int cols = std::min(S, fw.width - x0), rows = std::min(S, fw.height - y0);
  // Per pixel: current transmittance (after the Gaussian being visited), the incoming
  // gradients, the last blended index, and Q = T_final·∂L/∂A − Σ_behind w·(c·∂L/∂C + z·∂L/∂D),
  // the part of ∂L/∂α that the Gaussians behind contribute (times 1/(1 − α), see below).
  alignas(64) float T[S * S], Q[S * S];
  alignas(64) float gr[S * S], gg[S * S], gb[S * S], gd[S * S];
  alignas(64) int32_t last[S * S];
  alignas(64) float px_center[S];
  for (int i = 0; i < S; ++i) px_center[i] = x0 + i + 0.5f;
  int max_last = -1;
  for (int r = 0; r < S; ++r)
    for (int col = 0; col < S; ++col) {
      const int j = r * S + col;
      if (r < rows && col < cols) {
        const int64_t p = int64_t(y0 + r) * fw.width + (x0 + col);
        T[j] = fw.final_transmittance[p];
        last[j] = fw.last_contributor[p];
        gr[j] = dC ? dC[3 * p] : 0.0f;
        gg[j] = dC ? dC[3 * p + 1] : 0.0f;
        gb[j] = dC ? dC[3 * p + 2] : 0.0f;
        gd[j] = dD ? dD[p] : 0.0f;
        Q[j] = dA ? T[j] * dA[p] : 0.0f;
      } else {
        T[j] = 1, last[j] = -1;
        gr[j] = gg[j] = gb[j] = gd[j] = Q[j] = 0;
      }
      max_last = std::max(max_last, last[j]);
    }

  const int begin = fw.tile_offsets[tile], end = fw.tile_offsets[tile + 1];
  // Entries after the last blended one in every pixel get zero gradient.
  std::fill(entry_grads + size_t(begin + max_last + 1) * kEntrySlots, entry_grads + size_t(end) * kEntrySlots, 0.0f);
  for (int k = max_last; k >= 0; --k) {
    const int32_t g = fw.tile_entries[begin + k];
    const float mx = fw.means2d[2 * g], my = fw.means2d[2 * g + 1];
    const float a = fw.conics[3 * g], b = fw.conics[3 * g + 1], c = fw.conics[3 * g + 2];
    const float o = fw.opacity[g], z = fw.depths[g];
    const float cr = fw.rgb[3 * g], cg = fw.rgb[3 * g + 1], cb = fw.rgb[3 * g + 2];
    // Per-column partial sums, one lane per pixel column: elementwise updates vectorize,
    // and the lanes are summed in a fixed order afterwards (deterministic).
    alignas(64) float acc[kEntrySlots][S] = {};
    int r0, r1, h0, h1;
    box_rows_in_tile(my, fw.blend_radii[2 * g + 1], y0, rows, r0, r1);
    box_halves_in_tile(mx, fw.blend_radii[2 * g], x0, cols, h0, h1);
    for (int r = r0; r <= r1; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const int row = r * S;
      for (int h = h0; h <= h1; ++h)
#pragma omp simd
      for (int col = h * kHalfTile; col < (h + 1) * kHalfTile; ++col) {
        const int j = row + col;
        const float dx = mx - px_center[col];
        const float sigma = gaussian_sigma(a, b, c, dx, dy);
        const float vis = fast_exp_nonpositive(-sigma);
        const float alpha = clamp_alpha(o * vis);
        // Masks as 0/1 floats, built as chained selects: the body stays free of
        // branches and GCC vectorizes it (a `&`-combined condition defeats it).
        const float in_list = k <= last[j] ? 1.0f : 0.0f;
        const float in_sigma = sigma >= 0.0f ? in_list : 0.0f;
        const float hit = alpha >= kAlphaMin ? in_sigma : 0.0f;
        const float ra = 1.0f / (1.0f - alpha);
        const float t_before = T[j] * ra;  // transmittance in front of this Gaussian
        const float w = hit * alpha * t_before;
        // ∂C/∂α = c·T − (blended behind)/(1 − α) per channel, ∂A/∂α = T_final/(1 − α):
        // ∂L/∂α = T·(c·∂L/∂C + z·∂L/∂D) + Q/(1 − α).
        const float dot = cr * gr[j] + cg * gg[j] + cb * gb[j] + z * gd[j];
        const float d_alpha = t_before * dot + ra * Q[j];
        const float unclamped = o * vis <= kAlphaMax ? hit : 0.0f;
        const float d_sigma = -unclamped * d_alpha * o * vis;
        const float gmx = d_sigma * (a * dx + b * dy);
        const float gmy = d_sigma * (b * dx + c * dy);
        acc[kR][col] += w * gr[j];
        acc[kG][col] += w * gg[j];
        acc[kB][col] += w * gb[j];
        acc[kZ][col] += w * gd[j];
        acc[kO][col] += unclamped * d_alpha * vis;
        acc[kA][col] += 0.5f * d_sigma * dx * dx;
        acc[kB2][col] += d_sigma * dx * dy;
        acc[kC][col] += 0.5f * d_sigma * dy * dy;
        acc[kMx][col] += gmx;
        acc[kMy][col] += gmy;
        acc[kAbsX][col] += std::abs(gmx);
        acc[kAbsY][col] += std::abs(gmy);
        Q[j] -= w * dot;
        T[j] = hit > 0.0f ? t_before : T[j];
      }
    }
    // Columns of halves not visited hold +0, and adding +0 changes no sum: they are left out.
    float* record = entry_grads + size_t(begin + k) * kEntrySlots;
    for (int q = 0; q < kEntrySlots; ++q) {
      record[q] = 0;
      for (int col = h0 * kHalfTile; col < (h1 + 1) * kHalfTile; ++col) record[q] += acc[q][col];
    }
  }
}

}  // namespace

void rasterize_backward(const GaussianView& g, const Camera& cam, const RasterSettings& s,
                        const RasterOutput& fw, std::span<const float> dL_dcolor,
                        std::span<const float> dL_dalpha, std::span<const float> dL_ddepth,
                        RasterGradients& grads, std::span<const float> rgb_scale) {
  g.validate();
  cam.validate();
  const size_t n = g.size();
  const size_t pixels = size_t(cam.width) * cam.height;
  if (fw.width != cam.width || fw.height != cam.height || fw.visible.size() != n)
    throw std::invalid_argument("rasterize_backward: forward output does not match the camera or Gaussians");
  auto check = [](std::span<const float> v, size_t expect, const char* name) {
    if (!v.empty() && v.size() != expect)
      throw std::invalid_argument(std::string("rasterize_backward: ") + name + " has " +
                                  std::to_string(v.size()) + " values, expected " + std::to_string(expect));
  };
  check(dL_dcolor, 3 * pixels, "dL_dcolor");
  check(dL_dalpha, pixels, "dL_dalpha");
  check(dL_ddepth, pixels, "dL_ddepth");
  check(rgb_scale, 3 * n, "rgb_scale");

  const int color_stride = g.color_floats_per_gaussian();
  grads.means.assign(3 * n, 0.0f);
  grads.log_scales.assign(3 * n, 0.0f);
  grads.quats.assign(4 * n, 0.0f);
  grads.opacity_logits.assign(n, 0.0f);
  grads.colors.assign(color_stride * n, 0.0f);
  grads.means2d.assign(2 * n, 0.0f);
  grads.absgrad.assign(n, 0.0f);
  grads.rgb.assign(3 * n, 0.0f);

  const TileGrid grid(cam.width, cam.height);
  grads.entry_scratch.resize(fw.tile_entries.size() * kEntrySlots);
  float* entry_grads = grads.entry_scratch.data();
  const int threads = thread_count(s);
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
  for (int tile = 0; tile < grid.count(); ++tile)
    backward_tile(grid, tile, fw, dL_dcolor.empty() ? nullptr : dL_dcolor.data(),
                  dL_dalpha.empty() ? nullptr : dL_dalpha.data(),
                  dL_ddepth.empty() ? nullptr : dL_ddepth.data(), entry_grads);

  const PinholeIntrinsics K{cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height};
  const Mat3<float> W = Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>>(cam.R_cw.data());
  const Vec3<float> t(cam.t_cw[0], cam.t_cw[1], cam.t_cw[2]);
  const auto cc = cam.center();
  const Vec3<float> center(cc[0], cc[1], cc[2]);
  const bool sh_mode = g.color_mode == ColorMode::SphericalHarmonics;
  const int sh_degree = sh_mode ? (s.active_sh_degree < 0 ? g.sh_degree : s.active_sh_degree) : 0;

#pragma omp parallel for num_threads(threads) schedule(static)
  for (int64_t i = 0; i < static_cast<int64_t>(n); ++i) {
    if (!fw.visible[i]) continue;
    float sum[kEntrySlots] = {};
    for (int32_t e = fw.gaussian_offsets[i]; e < fw.gaussian_offsets[i + 1]; ++e) {
      const float* record = entry_grads + size_t(fw.entry_of_gaussian[e]) * kEntrySlots;
      for (int q = 0; q < kEntrySlots; ++q) sum[q] += record[q];
    }
    grads.means2d[2 * i] = sum[kMx];
    grads.means2d[2 * i + 1] = sum[kMy];
    grads.absgrad[i] = std::hypot(sum[kAbsX], sum[kAbsY]);

    // Opacity: o = sigmoid(logit).
    const float o = fw.opacity[i];
    grads.opacity_logits[i] = sum[kO] * o * (1.0f - o);

    // Color: the caller's change of the colour (rgb_scale), then the clamp, which passes the
    // gradient only where it was inactive.
    Vec3<float> d_rgb;
    for (int ch = 0; ch < 3; ++ch) {
      grads.rgb[3 * i + ch] = sum[kR + ch];
      const float scaled = rgb_scale.empty() ? sum[kR + ch] : rgb_scale[3 * i + ch] * sum[kR + ch];
      d_rgb[ch] = fw.color_clamped[3 * i + ch] ? 0.0f : scaled;
    }
    const Vec3<float> mean(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
    Vec3<float> d_mean = Vec3<float>::Zero();
    float* d_colors = &grads.colors[color_stride * i];
    if (sh_mode) {
      evaluate_color_sh_vjp(sh_degree, &g.colors[color_stride * i], mean, center, d_rgb, d_colors, d_mean);
    } else {
      for (int ch = 0; ch < 3; ++ch) d_colors[ch] = d_rgb[ch];
    }

    // Conic → 2D covariance → camera-space point and covariance → 3D parameters.
    const Vec3<float> conic(fw.conics[3 * i], fw.conics[3 * i + 1], fw.conics[3 * i + 2]);
    const Mat2<float> d_cov2d = conic_vjp(conic, Vec3<float>(sum[kA], sum[kB2], sum[kC]));
    const Vec3<float> p = W * mean + t;
    const Mat3<float> Sigma = covariance_3d<float>(&g.log_scales[3 * i], &g.quats[4 * i]);
    const Mat3<float> V = W * Sigma * W.transpose();
    Vec3<float> d_p;
    Mat3<float> d_V;
    project_ewa_vjp(p, V, K, Vec2<float>(sum[kMx], sum[kMy]), d_cov2d, sum[kZ], d_p, d_V);
    d_mean += W.transpose() * d_p;
    covariance_3d_vjp(&g.log_scales[3 * i], &g.quats[4 * i], W.transpose() * d_V * W,
                      &grads.log_scales[3 * i], &grads.quats[4 * i]);
    for (int k = 0; k < 3; ++k) grads.means[3 * i + k] = d_mean[k];
  }
}

}  // namespace desplat
