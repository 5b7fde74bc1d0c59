// The per-tile pixel loops of the forward and backward passes, written once and compiled
// once per instruction set: tile_kernels_<isa>.cpp defines
//   DESPLAT_TILE_NS         the namespace of this copy (portable, avx2, avx512), and
//   DESPLAT_TILE_FULL_ROWS  1 where a vector holds a whole 16-pixel tile row (AVX-512),
// then includes this file; its compiler flags pick the vector width (src/CMakeLists.txt).
// Everything here has internal linkage and the helpers it calls are inlined, so no
// function compiled for a wider instruction set can be picked by the linker for another
// file (tests/check_isa_symbols.sh checks the object files).
#include <algorithm>
#include <cmath>
#include <type_traits>

#include "raster/fast_exp.hpp"
#include "raster/stage_math.hpp"
#include "raster/tile_kernels.hpp"

namespace desplat::raster::DESPLAT_TILE_NS {
namespace {

// The pixel loops run over column spans with a compile-time width, so each becomes
// whole vectors: an 8-column half (one AVX2 vector), or with DESPLAT_TILE_FULL_ROWS a
// whole row when the Gaussian's box reaches both halves (one AVX-512 vector).
// `span(width, first_column)` is called for every span of row r the box reaches.
template <typename Span>
[[gnu::always_inline]] inline void for_each_span(int h0, int h1, Span&& span) {
  if (DESPLAT_TILE_FULL_ROWS && h0 == 0 && h1 == 1) {
    span(std::integral_constant<int, kTileSize>{}, 0);
    return;
  }
  for (int h = h0; h <= h1; ++h) span(std::integral_constant<int, kHalfTile>{}, h * kHalfTile);
}

// Front-to-back blending of one tile. Pixel state lives in 16×16 arrays; the inner
// loop over a span of a row is branch-free so it vectorizes.
int64_t blend_tile(const TileGrid& grid, int tile, RasterOutput& out) {
  constexpr int S = kTileSize;
  const int x0 = (tile % grid.tiles_x) * S, y0 = (tile / grid.tiles_x) * S;
  const int cols = std::min(S, out.width - x0), rows = std::min(S, out.height - y0);
  if (out.tile_offsets[tile] == out.tile_offsets[tile + 1]) {  // no Gaussian: the empty render
    for (int r = 0; r < rows; ++r) {
      const int64_t p0 = int64_t(y0 + r) * out.width + x0;
      std::fill_n(&out.color[3 * p0], 3 * cols, 0.0f);
      std::fill_n(&out.alpha[p0], cols, 0.0f);
      std::fill_n(&out.depth[p0], cols, 0.0f);
      std::fill_n(&out.final_transmittance[p0], cols, 1.0f);
      std::fill_n(&out.last_contributor[p0], cols, -1);
    }
    return 0;
  }
  alignas(64) float T[S * S], Cr[S * S], Cg[S * S], Cb[S * S], D[S * S];
  alignas(64) int32_t active[S * S], last[S * S];
  alignas(64) float px_center[S];
  for (int i = 0; i < S; ++i) px_center[i] = x0 + i + 0.5f;
  int remaining = 0;
  for (int r = 0; r < S; ++r)
    for (int col = 0; col < S; ++col) {
      const int j = r * S + col;
      T[j] = 1, Cr[j] = Cg[j] = Cb[j] = D[j] = 0, last[j] = -1;
      active[j] = (r < rows && col < cols);
      remaining += active[j];
    }

  int64_t evaluated = 0;
  const int begin = out.tile_offsets[tile], end = out.tile_offsets[tile + 1];
  for (int k = 0; k < end - begin && remaining > 0; ++k) {
    const int32_t g = out.tile_entries[begin + k];
    const float mx = out.means2d[2 * g], my = out.means2d[2 * g + 1];
    const float a = out.conics[3 * g], b = out.conics[3 * g + 1], c = out.conics[3 * g + 2];
    const float o = out.opacity[g], z = out.depths[g];
    const float cr = out.rgb[3 * g], cg = out.rgb[3 * g + 1], cb = out.rgb[3 * g + 2];
    int r0, r1, h0, h1;
    box_rows_in_tile(my, out.blend_radii[2 * g + 1], y0, rows, r0, r1);
    box_halves_in_tile(mx, out.blend_radii[2 * g], x0, cols, h0, h1);
    if (h0 > h1) continue;
    const RowChords chords(&out.chords[kChordFloats * g], mx, x0, h0, h1);
    // Pixels that stopped at this entry, per column; summed once per entry rather than per row.
    alignas(64) int32_t finished[S] = {};
    alignas(64) int32_t row_h0[S], row_h1[S];
    chords.row_halves(my, y0, row_h0, row_h1);
    for (int r = r0; r <= r1; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const int row = r * S;
      const int rh0 = row_h0[r], rh1 = row_h1[r];
      if (rh0 > rh1) continue;
      evaluated += (rh1 - rh0 + 1) * kHalfTile;
      for_each_span(rh0, rh1, [&](auto width, int first) {
#pragma omp simd
        for (int col = first; col < first + decltype(width)::value; ++col) {
          const int j = row + col;
          const float dx = mx - px_center[col];
          const float sigma = gaussian_sigma(a, b, c, dx, dy);
          const float alpha = clamp_alpha(o * fast_exp_nonpositive(-sigma));
          const float t = T[j];
          const float next_t = t * (1.0f - alpha);
          // 0/1 int32 masks, not bool: GCC (12) vectorizes for AVX2 only when every lane
          // value is 32 bits wide and nothing is evaluated conditionally (no && chains).
          const int32_t hit = active[j] & int32_t(sigma >= 0.0f) & int32_t(alpha >= kAlphaMin);
          const int32_t finish = hit & int32_t(next_t <= kTransmittanceMin);  // not blended
          const int32_t blend = hit & (finish ^ 1);
          const float weight = alpha * t;
          const float w = blend ? weight : 0.0f;
          Cr[j] += w * cr;
          Cg[j] += w * cg;
          Cb[j] += w * cb;
          D[j] += w * z;
          T[j] = blend ? next_t : t;
          last[j] = blend ? k : last[j];
          active[j] = finish ? 0 : active[j];
          finished[col] += finish;
        }
      });
    }
    for (int col = 0; col < S; ++col) remaining -= finished[col];
  }

  for (int r = 0; r < rows; ++r)
    for (int col = 0; col < cols; ++col) {
      const int j = r * S + col;
      const int64_t p = int64_t(y0 + r) * out.width + (x0 + col);
      out.color[3 * p] = Cr[j];
      out.color[3 * p + 1] = Cg[j];
      out.color[3 * p + 2] = Cb[j];
      out.alpha[p] = 1.0f - T[j];
      out.depth[p] = D[j];
      out.final_transmittance[p] = T[j];
      out.last_contributor[p] = last[j];
    }
  return evaluated;
}

// Back-to-front walk of one tile: per (tile, Gaussian) entry, the gradient with respect to
// the Gaussian's 2D quantities from this tile's pixels (docs/METHOD.md §3).
void backward_tile(const TileGrid& grid, int tile, const RasterOutput& fw, const float* dC,
                   const float* dA, const float* dD, float* entry_grads) {
  constexpr int S = kTileSize;
  const int x0 = (tile % grid.tiles_x) * S, y0 = (tile / grid.tiles_x) * S;
  const int cols = std::min(S, fw.width - x0), rows = std::min(S, fw.height - y0);
  if (fw.tile_offsets[tile] == fw.tile_offsets[tile + 1]) return;  // no entries, no records
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
  for (int e = begin + max_last + 1; e < end; ++e)
    std::fill_n(entry_grads + size_t(fw.record_of_entry[e]) * kEntrySlots, kEntrySlots, 0.0f);
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
    const RowChords chords(&fw.chords[kChordFloats * g], mx, x0, h0, h1);
    alignas(64) int32_t row_h0[S], row_h1[S];
    chords.row_halves(my, y0, row_h0, row_h1);
    for (int r = r0; r <= r1; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const int row = r * S;
      const int rh0 = row_h0[r], rh1 = row_h1[r];
      if (rh0 > rh1) continue;
      for_each_span(rh0, rh1, [&](auto width, int first) {
#pragma omp simd
        for (int col = first; col < first + decltype(width)::value; ++col) {
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
      });
    }
    // Columns of halves not visited hold +0, and adding +0 changes no sum: they are left out.
    float* record = entry_grads + size_t(fw.record_of_entry[begin + k]) * kEntrySlots;
    for (int q = 0; q < kEntrySlots; ++q) {
      record[q] = 0;
      for (int col = h0 * kHalfTile; col < (h1 + 1) * kHalfTile; ++col) record[q] += acc[q][col];
    }
  }
}

}  // namespace

extern const TileKernels kTileKernels{&blend_tile, &backward_tile};

}  // namespace desplat::raster::DESPLAT_TILE_NS
