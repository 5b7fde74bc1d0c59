// Forward pass: per-Gaussian projection, tile binning, per-tile front-to-back blending.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

#include "raster/gaussian_lanes.hpp"
#include "raster/prefetch.hpp"
#include "raster/stage_math.hpp"
#include "raster/tile_kernels.hpp"
#include "raster/tiles.hpp"

namespace desplat {
namespace {
using namespace raster;

int effective_sh_degree(const GaussianView& g, const RasterSettings& s) {
  if (g.color_mode == ColorMode::RGB) return 0;
  const int d = s.active_sh_degree < 0 ? g.sh_degree : s.active_sh_degree;
  if (d > g.sh_degree)
    throw std::invalid_argument("active SH degree " + std::to_string(d) + " exceeds the stored SH degree " +
                                std::to_string(g.sh_degree));
  return d;
}

// Projection, culling, color and opacity for every Gaussian (docs/METHOD.md §3). The
// geometry runs kLanes Gaussians at a time in vector lanes (gaussian_lanes.hpp); colour,
// opacity and the blend box follow per visible Gaussian.
void preprocess(const GaussianView& g, const Camera& cam, const RasterSettings& s, int sh_degree, RasterOutput& out) {
  const int64_t n = static_cast<int64_t>(g.size());
  const PinholeIntrinsics K{cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height};
  const LaneCamera lane_cam(cam.R_cw.data(), cam.t_cw.data(), K, s.eps2d, s.near_plane, s.far_plane);
  const auto c = cam.center();
  const Vec3<float> center(c[0], c[1], c[2]);
  const bool sh_mode = g.color_mode == ColorMode::SphericalHarmonics;
  const int color_stride = g.color_floats_per_gaussian();
  const int64_t blocks = (n + kLanes - 1) / kLanes;

#pragma omp parallel for num_threads(thread_count(s)) schedule(static)
  for (int64_t b = 0; b < blocks; ++b) {
    const int64_t i0 = b * kLanes;
    const int lanes = static_cast<int>(std::min<int64_t>(kLanes, n - i0));
    LaneGaussians in;
    for (int l = 0; l < kLanes; ++l) {
      const int64_t i = i0 + std::min(l, lanes - 1);
      for (int k = 0; k < 3; ++k)
        in.mean[k][l] = g.means[3 * i + k], in.scale[k][l] = std::exp(g.log_scales[3 * i + k]);
      for (int k = 0; k < 4; ++k) in.quat[k][l] = g.quats[4 * i + k];
      if (l >= lanes) in.mean[2][l] = NAN;  // padding: never visible
    }
    for (int l = 0; l < lanes; ++l)
      for (int k = 0; k < 3; ++k) out.scales[3 * (i0 + l) + k] = in.scale[k][l];
    LaneGeometry geometry;
    geometry_lanes(lane_cam, in, geometry);
    LaneProjection proj;
    project_lanes(lane_cam, in, geometry.V, proj);

    for (int l = 0; l < lanes; ++l) {
      const int64_t i = i0 + l;
      if (const int64_t ahead = i + kRowPrefetchDistance; ahead < n)
        prefetch_row_for_read(&g.colors[color_stride * ahead], color_stride);
      if (!proj.visible[l]) {
        // An invisible Gaussian's entries are zero (raster.hpp).
        out.radii[2 * i] = out.radii[2 * i + 1] = 0;
        out.blend_radii[2 * i] = out.blend_radii[2 * i + 1] = 0;
        out.visible[i] = 0;
        out.means2d[2 * i] = out.means2d[2 * i + 1] = 0.0f;
        for (int k = 0; k < 3; ++k) out.conics[3 * i + k] = out.rgb[3 * i + k] = 0.0f, out.color_clamped[3 * i + k] = 0;
        for (int k = 0; k < kChordFloats; ++k) out.splats[i].chord[k] = 0.0f;
        out.depths[i] = out.opacity[i] = 0.0f;
        continue;
      }
      const Vec3<float> mean(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
      const float opacity = sigmoid(g.opacity_logits[i]);
      Vec3<float> color = evaluate_color<float>(sh_mode, sh_degree, &g.colors[color_stride * i], mean, center);
      for (int ch = 0; ch < 3; ++ch) {
        const float lo = 0.0f, hi = sh_mode ? INFINITY : 1.0f;
        out.color_clamped[3 * i + ch] = !(color[ch] >= lo && color[ch] <= hi);
        color[ch] = std::clamp(std::isfinite(color[ch]) ? color[ch] : 0.0f, lo, hi);
      }
      out.means2d[2 * i] = proj.mean2d[0][l];
      out.means2d[2 * i + 1] = proj.mean2d[1][l];
      for (int k = 0; k < 3; ++k) out.conics[3 * i + k] = proj.conic[k][l];
      const float rx = proj.radius[0][l], ry = proj.radius[1][l];
      out.radii[2 * i] = static_cast<int32_t>(rx);
      out.radii[2 * i + 1] = static_cast<int32_t>(ry);
      // Tiles and rows are visited only where α can reach 1/255; the 3.33σ radii above still
      // decide visibility and the screen size that density control reads.
      const float k = opacity_extent_sigmas(opacity);
      out.blend_radii[2 * i] = static_cast<int32_t>(std::min(rx, std::ceil(k * std::sqrt(proj.cov2d[0][l]))));
      out.blend_radii[2 * i + 1] = static_cast<int32_t>(std::min(ry, std::ceil(k * std::sqrt(proj.cov2d[2][l]))));
      chord_shape(proj.conic[0][l], proj.conic[1][l], proj.conic[2][l], opacity, out.blend_radii[2 * i],
                  out.blend_radii[2 * i + 1], out.splats[i].chord);
      out.depths[i] = proj.p[2][l];
      out.opacity[i] = opacity;
      for (int ch = 0; ch < 3; ++ch) out.rgb[3 * i + ch] = color[ch];
      out.visible[i] = 1;
    }
  }
}

// Sorts keys (depth bits << 32 | id) that were appended in increasing id by their depth:
// a stable LSD radix sort on the depth's 32 bits, three digits of 11 bits. Stability keeps
// equal depths in id order, so the result is the ascending order of the whole keys, as a
// comparison sort of them gives, in three linear passes (a digit all keys share is skipped).
void sort_by_depth(std::vector<uint64_t>& keys, std::vector<uint64_t>& scratch) {
  constexpr int kDigitBits = 11;
  constexpr uint64_t kDigitMask = (1u << kDigitBits) - 1;
  if (keys.size() < 2) return;
  scratch.resize(keys.size());
  for (int shift = 32; shift < 64; shift += kDigitBits) {
    std::array<uint32_t, kDigitMask + 1> start{};
    for (uint64_t k : keys) ++start[(k >> shift) & kDigitMask];
    if (start[(keys[0] >> shift) & kDigitMask] == keys.size()) continue;
    uint32_t sum = 0;
    for (uint32_t& c : start) sum += std::exchange(c, sum);
    for (uint64_t k : keys) scratch[start[(k >> shift) & kDigitMask]++] = k;
    keys.swap(scratch);
  }
}

// The binning's working arrays, kept between calls on the calling thread so a training step
// allocates none of them; their contents mean nothing between calls.
struct Listed {  // a Gaussian in depth order, with what the fill reads of it
  int32_t id, first_record;
  TileRect rect;
};
struct BinScratch {
  std::vector<TileRect> rects;
  std::vector<std::vector<uint64_t>> chunk_keys, chunk_scratch;
  std::vector<int32_t> chunk_counts;
  std::vector<uint64_t> keys, merged;
  std::vector<Listed> listed;
};

// Builds the depth-sorted per-tile work lists. Visible Gaussians are sorted once by
// (depth, id) and appended to their tiles in that order, which yields the same per-tile
// order as gsplat's radix sort of (tile, depth) keys. The fill runs in parallel over
// bands of tile rows: each thread walks the whole depth order but writes only its own
// tiles, so there are no races and the result does not depend on the thread count.
void bin_gaussians(const TileGrid& grid, int threads, RasterOutput& out) {
  static thread_local BinScratch scratch;
  const int64_t n = static_cast<int64_t>(out.visible.size());
  // Each Gaussian's tiles, worked out once: none when α < 1/255 everywhere.
  std::vector<TileRect>& rects = scratch.rects;
  rects.resize(n);
  out.gaussian_offsets.assign(n + 1, 0);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (int64_t i = 0; i < n; ++i) {
    // Visible: the 3.33σ box touches a tile (it may still be listed in none, when its
    // opacity keeps α below 1/255 everywhere in the image).
    if (out.visible[i] &&
        tile_rect(grid, out.means2d[2 * i], out.means2d[2 * i + 1], out.radii[2 * i], out.radii[2 * i + 1]).area() == 0)
      out.visible[i] = 0;
    const bool blended = out.visible[i] && out.blend_radii[2 * i] != 0 && out.blend_radii[2 * i + 1] != 0;
    rects[i] = blended ? tile_rect(grid, out.means2d[2 * i], out.means2d[2 * i + 1], out.blend_radii[2 * i],
                                   out.blend_radii[2 * i + 1])
                       : TileRect{0, 0, 0, 0};
    const int listed = rects[i].area();
    out.gaussian_offsets[i + 1] = listed;
    if (listed == 0) continue;
    TileSplat& sp = out.splats[i];
    sp.mx = out.means2d[2 * i], sp.my = out.means2d[2 * i + 1];
    for (int k = 0; k < 3; ++k) sp.conic[k] = out.conics[3 * i + k], sp.rgb[k] = out.rgb[3 * i + k];
    sp.opacity = out.opacity[i], sp.depth = out.depths[i];
    sp.rx = out.blend_radii[2 * i], sp.ry = out.blend_radii[2 * i + 1];
  }
  // Depth is > near > 0, so its float bits order like the value: (bits << 32 | id)
  // sorts by depth, then id, with plain integer compares. The keys are unique, so sorting
  // contiguous chunks of ids on the threads and merging them gives the one sorted order
  // whatever the thread count; each chunk also counts its Gaussians' entries per tile.
  const int chunks = std::max(1, threads);
  const int tiles = grid.count();
  std::vector<std::vector<uint64_t>>&chunk_keys = scratch.chunk_keys, &chunk_scratch = scratch.chunk_scratch;
  chunk_keys.resize(chunks), chunk_scratch.resize(chunks);
  std::vector<int32_t>& chunk_counts = scratch.chunk_counts;
  chunk_counts.assign(size_t(chunks) * tiles, 0);
#pragma omp parallel for num_threads(threads) schedule(static, 1)
  for (int ch = 0; ch < chunks; ++ch) {
    const int64_t lo = n * ch / chunks, hi = n * (ch + 1) / chunks;
    std::vector<uint64_t>& keys = chunk_keys[ch];
    keys.clear();
    keys.reserve(size_t(hi - lo));
    int32_t* counts = &chunk_counts[size_t(ch) * tiles];
    for (int64_t i = lo; i < hi; ++i) {
      if (!out.visible[i]) continue;
      keys.push_back(uint64_t(std::bit_cast<uint32_t>(out.depths[i])) << 32 | uint64_t(i));
      const TileRect r = rects[i];
      for (int ty = r.y0; ty < r.y1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx) ++counts[ty * grid.tiles_x + tx];
    }
    sort_by_depth(keys, chunk_scratch[ch]);
  }
  // The merged order ends in `keys` (swapped with chunk 0's buffer, whose capacity comes
  // back to the scratch either way).
  std::vector<uint64_t>&keys = scratch.keys, &merged = scratch.merged;
  keys.swap(chunk_keys[0]);
  for (int ch = 1; ch < chunks; ++ch) {
    merged.resize(keys.size() + chunk_keys[ch].size());
    std::merge(keys.begin(), keys.end(), chunk_keys[ch].begin(), chunk_keys[ch].end(), merged.begin());
    keys.swap(merged);
  }
  std::partial_sum(out.gaussian_offsets.begin(), out.gaussian_offsets.end(), out.gaussian_offsets.begin());
  const int64_t entries = out.gaussian_offsets[n];
  if (entries > INT32_MAX) throw std::runtime_error("too many tile–Gaussian intersections");
  // The Gaussians in depth order with what the fill reads of each, so its threads walk one
  // array in order instead of gathering from three by id. Built on the threads; a Gaussian
  // listed in no tile keeps its empty rectangle, which the fill passes over.
  std::vector<Listed>& listed = scratch.listed;
  listed.resize(keys.size());
#pragma omp parallel for num_threads(threads) schedule(static)
  for (size_t k = 0; k < keys.size(); ++k) {
    const int32_t i = static_cast<int32_t>(keys[k] & 0xffffffffu);
    listed[k] = {i, out.gaussian_offsets[i], rects[i]};
  }

  // Tile counts (summed over the chunks), then CSR offsets.
  out.tile_offsets.assign(tiles + 1, 0);
  for (int ch = 0; ch < chunks; ++ch)
    for (int t = 0; t < tiles; ++t) out.tile_offsets[t + 1] += chunk_counts[size_t(ch) * tiles + t];
  std::partial_sum(out.tile_offsets.begin(), out.tile_offsets.end(), out.tile_offsets.begin());
  out.tile_entries.resize(entries);
  out.record_of_entry.resize(entries);
  out.entry_blank.resize(entries);  // written by the pixel loops for the entries they visit

  // Bands of tile rows with about equal numbers of entries.
  const int bands = std::min(threads, grid.tiles_y);
  std::vector<int> band_start(bands + 1, grid.tiles_y);
  band_start[0] = 0;
  for (int b = 1, ty = 0; b < bands; ++b) {
    while (ty < grid.tiles_y && out.tile_offsets[ty * grid.tiles_x] < entries * b / bands) ++ty;
    band_start[b] = ty;
  }
#pragma omp parallel for num_threads(threads) schedule(static, 1)
  for (int b = 0; b < bands; ++b) {
    const int y_lo = band_start[b], y_hi = band_start[b + 1];
    if (y_lo >= y_hi) continue;
    std::vector<int32_t> cursor(out.tile_offsets.begin() + y_lo * grid.tiles_x,
                                out.tile_offsets.begin() + y_hi * grid.tiles_x);
    for (const Listed& g : listed) {
      const TileRect& r = g.rect;
      const int ty0 = std::max(r.y0, y_lo), ty1 = std::min(r.y1, y_hi);
      for (int ty = ty0; ty < ty1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx) {
          const int32_t pos = cursor[(ty - y_lo) * grid.tiles_x + tx]++;
          out.tile_entries[pos] = g.id;
          // A Gaussian's records follow row-major order over its rectangle.
          out.record_of_entry[pos] = g.first_record + (ty - r.y0) * (r.x1 - r.x0) + (tx - r.x0);
        }
    }
  }
}

}  // namespace

void rasterize_project(const GaussianView& g, const Camera& cam, const RasterSettings& s, RasterOutput& out) {
  g.validate();
  cam.validate();
  const int sh_degree = effective_sh_degree(g, s);
  const size_t n = g.size();
  out.width = cam.width;
  out.height = cam.height;
  // Sized here, filled on the threads by preprocess (every entry of every Gaussian).
  out.means2d.resize(2 * n);
  out.conics.resize(3 * n);
  out.radii.resize(2 * n);
  out.depths.resize(n);
  out.visible.resize(n);
  out.rgb.resize(3 * n);
  out.opacity.resize(n);
  out.color_clamped.resize(3 * n);
  out.blend_radii.resize(2 * n);
  out.scales.resize(3 * n);
  out.splats.resize(n);  // the chord shape now, the rest when the tiles are binned
  preprocess(g, cam, s, sh_degree, out);
}

void rasterize_blend(const Camera& cam, const RasterSettings& s, RasterOutput& out) {
  if (out.width != cam.width || out.height != cam.height)
    throw std::invalid_argument("rasterize_blend: the projection was made for another image size");
  // Every pixel belongs to one tile and blend_tile writes all of them: no fill needed.
  const size_t pixels = size_t(cam.width) * cam.height;
  out.color.resize(3 * pixels);
  out.alpha.resize(pixels);
  out.depth.resize(pixels);
  out.final_transmittance.resize(pixels);
  out.last_contributor.resize(pixels);
  out.isa = resolve_kernel_isa(s.isa);
  const TileKernels& kernels = tile_kernels(out.isa);
  const TileGrid grid(cam.width, cam.height);
  bin_gaussians(grid, thread_count(s), out);

  int64_t evaluated = 0;
#pragma omp parallel for num_threads(thread_count(s)) schedule(dynamic, 1) reduction(+ : evaluated)
  for (int tile = 0; tile < grid.count(); ++tile) evaluated += kernels.blend_tile(grid, tile, out);
  out.evaluated_pairs = evaluated;
}

void rasterize_forward(const GaussianView& g, const Camera& cam, const RasterSettings& s, RasterOutput& out) {
  rasterize_project(g, cam, s, out);
  rasterize_blend(cam, s, out);
}

}  // namespace desplat
