// Backward pass. Each tile walks its list back to front and writes, per (tile,
// Gaussian) entry, the gradient with respect to that Gaussian's 2D quantities. Then
// each Gaussian sums its entries in a fixed order and chains through color, opacity,
// conic and projection to its 3D parameters. No atomics; results do not depend on the
// thread count or the schedule.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "raster/gaussian_lanes.hpp"
#include "raster/prefetch.hpp"
#include "raster/stage_math.hpp"
#include "raster/tile_kernels.hpp"
#include "raster/tiles.hpp"

namespace desplat {
using namespace raster;

void rasterize_backward(const GaussianView& g, const Camera& cam, const RasterSettings& s, const RasterOutput& fw,
                        std::span<const float> dL_dcolor, std::span<const float> dL_dalpha,
                        std::span<const float> dL_ddepth, RasterGradients& grads, std::span<const float> rgb_scale) {
  g.validate();
  cam.validate();
  const size_t n = g.size();
  const size_t pixels = size_t(cam.width) * cam.height;
  if (fw.width != cam.width || fw.height != cam.height || fw.visible.size() != n || fw.scales.size() != 3 * n)
    throw std::invalid_argument("rasterize_backward: forward output does not match the camera or Gaussians");
  auto check = [](std::span<const float> v, size_t expect, const char* name) {
    if (!v.empty() && v.size() != expect)
      throw std::invalid_argument(std::string("rasterize_backward: ") + name + " has " + std::to_string(v.size()) +
                                  " values, expected " + std::to_string(expect));
  };
  check(dL_dcolor, 3 * pixels, "dL_dcolor");
  check(dL_dalpha, pixels, "dL_dalpha");
  check(dL_ddepth, pixels, "dL_ddepth");
  check(rgb_scale, 3 * n, "rgb_scale");

  const int color_stride = g.color_floats_per_gaussian();
  // Sized here, zeroed row by row on the threads in the per-Gaussian loop below.
  grads.means.resize(3 * n);
  grads.log_scales.resize(3 * n);
  grads.quats.resize(4 * n);
  grads.opacity_logits.resize(n);
  grads.colors.resize(color_stride * n);
  grads.means2d.resize(2 * n);
  grads.absgrad.resize(n);
  grads.rgb.resize(3 * n);

  const TileGrid grid(cam.width, cam.height);
  grads.entry_scratch.resize(fw.tile_entries.size() * kEntrySlots);
  float* entry_grads = grads.entry_scratch.data();
  const int threads = thread_count(s);
  // The forward's path: it recomputes each α with the same bits (raster.hpp, KernelIsa).
  const TileKernels& kernels = tile_kernels(fw.isa);
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
  for (int tile = 0; tile < grid.count(); ++tile)
    kernels.backward_tile(grid, tile, fw, dL_dcolor.empty() ? nullptr : dL_dcolor.data(),
                          dL_dalpha.empty() ? nullptr : dL_dalpha.data(),
                          dL_ddepth.empty() ? nullptr : dL_ddepth.data(), entry_grads);

  const PinholeIntrinsics K{cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height};
  const LaneCamera lane_cam(cam.R_cw.data(), cam.t_cw.data(), K, s.eps2d, s.near_plane, s.far_plane);
  const auto cc = cam.center();
  const Vec3<float> center(cc[0], cc[1], cc[2]);
  const bool sh_mode = g.color_mode == ColorMode::SphericalHarmonics;
  const int sh_degree = sh_mode ? (s.active_sh_degree < 0 ? g.sh_degree : s.active_sh_degree) : 0;
  const int64_t count = static_cast<int64_t>(n);
  const int64_t blocks = (count + kLanes - 1) / kLanes;

  // Per block of kLanes Gaussians: sum each one's entries, chain opacity and colour one by
  // one, then the geometry (conic → projection → scales and rotation) in vector lanes.
#pragma omp parallel for num_threads(threads) schedule(static)
  for (int64_t b = 0; b < blocks; ++b) {
    const int64_t i0 = b * kLanes;
    const int lanes = static_cast<int>(std::min<int64_t>(kLanes, count - i0));
    LaneGaussians geo;
    LaneGradientsIn d_in;
    bool any_visible = false;
    for (int l = 0; l < kLanes; ++l) {
      const int64_t i = i0 + std::min(l, lanes - 1);
      const bool used = l < lanes && fw.visible[i];
      any_visible |= used;
      // The forward's exp(log_scales), read rather than recomputed (the same values).
      for (int k = 0; k < 3; ++k) geo.mean[k][l] = g.means[3 * i + k], geo.scale[k][l] = fw.scales[3 * i + k];
      for (int k = 0; k < 4; ++k) geo.quat[k][l] = g.quats[4 * i + k];
      for (int k = 0; k < 3; ++k) d_in.conic[k][l] = fw.conics[3 * i + k], d_in.d_conic[k][l] = 0.0f;
      d_in.d_mean2d[0][l] = d_in.d_mean2d[1][l] = d_in.d_depth[l] = 0.0f;
    }

    for (int l = 0; l < lanes; ++l) {
      const int64_t i = i0 + l;
      // Zero the row first: an invisible Gaussian's gradient is zero, and the chain rule
      // below adds into the colour gradients.
      std::fill_n(&grads.means[3 * i], 3, 0.0f);
      std::fill_n(&grads.log_scales[3 * i], 3, 0.0f);
      std::fill_n(&grads.quats[4 * i], 4, 0.0f);
      std::fill_n(&grads.colors[color_stride * i], color_stride, 0.0f);
      std::fill_n(&grads.means2d[2 * i], 2, 0.0f);
      std::fill_n(&grads.rgb[3 * i], 3, 0.0f);
      grads.opacity_logits[i] = grads.absgrad[i] = 0.0f;
      if (const int64_t ahead = i + kRowPrefetchDistance; ahead < count) {
        prefetch_row_for_read(&g.colors[color_stride * ahead], color_stride);
        prefetch_row_for_write(&grads.colors[color_stride * ahead], color_stride);
      }
      if (!fw.visible[i]) continue;
      // A fixed-size array so the 12 slots add as three 4-wide vectors (a plain loop compiled
      // to scalar adds); each slot still sums its entries in the same order, so the bits hold.
      using EntryRecord = Eigen::Array<float, kEntrySlots, 1>;
      EntryRecord sum = EntryRecord::Zero();
      for (int32_t e = fw.gaussian_offsets[i]; e < fw.gaussian_offsets[i + 1]; ++e)
        sum += Eigen::Map<const EntryRecord>(entry_grads + size_t(e) * kEntrySlots);
      grads.means2d[2 * i] = sum[kMx];
      grads.means2d[2 * i + 1] = sum[kMy];
      grads.absgrad[i] = std::hypot(sum[kAbsX], sum[kAbsY]);
      d_in.d_mean2d[0][l] = sum[kMx], d_in.d_mean2d[1][l] = sum[kMy];
      d_in.d_conic[0][l] = sum[kA], d_in.d_conic[1][l] = sum[kB2], d_in.d_conic[2][l] = sum[kC];
      d_in.d_depth[l] = sum[kZ];

      // Opacity: o = sigmoid(logit).
      const float o = fw.opacity[i];
      grads.opacity_logits[i] = sum[kO] * o * (1.0f - o);

      // Color: the caller's change of the colour (rgb_scale), then the clamp, which passes the
      // gradient only where it was inactive. Its pull on the mean (SH direction) goes into
      // grads.means, to which the projection's share is added below.
      Vec3<float> d_rgb;
      for (int ch = 0; ch < 3; ++ch) {
        grads.rgb[3 * i + ch] = sum[kR + ch];
        const float scaled = rgb_scale.empty() ? sum[kR + ch] : rgb_scale[3 * i + ch] * sum[kR + ch];
        d_rgb[ch] = fw.color_clamped[3 * i + ch] ? 0.0f : scaled;
      }
      float* d_colors = &grads.colors[color_stride * i];
      if (sh_mode) {
        const Vec3<float> mean(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
        Vec3<float> d_mean = Vec3<float>::Zero();
        evaluate_color_sh_vjp(sh_degree, &g.colors[color_stride * i], mean, center, d_rgb, d_colors, d_mean);
        for (int k = 0; k < 3; ++k) grads.means[3 * i + k] = d_mean[k];
      } else {
        for (int ch = 0; ch < 3; ++ch) d_colors[ch] = d_rgb[ch];
      }
    }
    if (!any_visible) continue;

    LaneGeometry geometry;
    geometry_lanes(lane_cam, geo, geometry);
    LaneGradientsOut d_out;
    backward_lanes(lane_cam, geo, geometry.rot, geometry.V, d_in, d_out);
    for (int l = 0; l < lanes; ++l) {
      const int64_t i = i0 + l;
      if (!fw.visible[i]) continue;
      for (int k = 0; k < 3; ++k) grads.means[3 * i + k] += d_out.d_mean[k][l];
      for (int k = 0; k < 3; ++k) grads.log_scales[3 * i + k] = d_out.d_log_scale[k][l];
      for (int k = 0; k < 4; ++k) grads.quats[4 * i + k] = d_out.d_quat[k][l];
    }
  }
}

}  // namespace desplat
