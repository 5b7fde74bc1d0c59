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

#if DESPLAT_TILE_FULL_ROWS
#include <immintrin.h>
#endif

#include "raster/fast_exp.hpp"
#include "raster/stage_math.hpp"
#include "raster/tile_kernels.hpp"

namespace desplat::raster::DESPLAT_TILE_NS {
namespace {

// How many tile entries ahead the pixel loops prefetch a Gaussian's TileSplat.
constexpr int kSplatPrefetch = 2;

// record[q] = Σ acc[q][col] over columns [c0, c1), each slot summed column after column from
// +0: the order (and so the bits) of a plain scalar loop.
[[gnu::always_inline]] inline void sum_columns(const float (&acc)[kEntrySlots][kTileSize], int c0, int c1,
                                               float* record) {
#if DESPLAT_TILE_FULL_ROWS
  // One AVX-512 vector per slot row, transposed in registers to one vector per column (lane q
  // = slot q), so the 12 running sums advance together: one vector add per column instead
  // of 12 dependent scalar chains.
  static_assert(kTileSize == 16 && kEntrySlots <= 16);
  __m512 r[16];
  for (int q = 0; q < 16; ++q) r[q] = q < kEntrySlots ? _mm512_load_ps(acc[q]) : _mm512_setzero_ps();
  __m512 a[16], b[16];
  for (int i = 0; i < 8; ++i) {  // 32-bit interleave of row pairs, within 128-bit lanes
    a[2 * i] = _mm512_unpacklo_ps(r[2 * i], r[2 * i + 1]);
    a[2 * i + 1] = _mm512_unpackhi_ps(r[2 * i], r[2 * i + 1]);
  }
  for (int i = 0; i < 4; ++i) {  // 64-bit interleave: lane k of b[4i + j] = column 4k + j, rows 4i..4i+3
    auto lo = [](__m512 x, __m512 y) {
      return _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(x), _mm512_castps_pd(y)));
    };
    auto hi = [](__m512 x, __m512 y) {
      return _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(x), _mm512_castps_pd(y)));
    };
    b[4 * i + 0] = lo(a[4 * i], a[4 * i + 2]);
    b[4 * i + 1] = hi(a[4 * i], a[4 * i + 2]);
    b[4 * i + 2] = lo(a[4 * i + 1], a[4 * i + 3]);
    b[4 * i + 3] = hi(a[4 * i + 1], a[4 * i + 3]);
  }
  __m512 column[16];
  for (int j = 0; j < 4; ++j) {  // gather lane k of the four row groups: column 4k + j
    const __m512 g0 = _mm512_shuffle_f32x4(b[j], b[4 + j], 0x88), g1 = _mm512_shuffle_f32x4(b[j], b[4 + j], 0xDD);
    const __m512 g2 = _mm512_shuffle_f32x4(b[8 + j], b[12 + j], 0x88),
                 g3 = _mm512_shuffle_f32x4(b[8 + j], b[12 + j], 0xDD);
    column[j] = _mm512_shuffle_f32x4(g0, g2, 0x88);
    column[8 + j] = _mm512_shuffle_f32x4(g0, g2, 0xDD);
    column[4 + j] = _mm512_shuffle_f32x4(g1, g3, 0x88);
    column[12 + j] = _mm512_shuffle_f32x4(g1, g3, 0xDD);
  }
  __m512 sum = _mm512_setzero_ps();
  for (int col = c0; col < c1; ++col) sum = _mm512_add_ps(sum, column[col]);
  _mm512_mask_storeu_ps(record, __mmask16((1u << kEntrySlots) - 1), sum);
#else
  for (int q = 0; q < kEntrySlots; ++q) {
    record[q] = 0;
    for (int col = c0; col < c1; ++col) record[q] += acc[q][col];
  }
#endif
}

// The pixel loops run over column spans with a compile-time width, so each becomes whole
// vectors. `span(width, first_column)` is called for the halves [h0, h1] of a row the
// Gaussian's chord reaches: once per 8-column half (one AVX2 vector), or with
// DESPLAT_TILE_FULL_ROWS once per row, all 16 columns (one AVX-512 vector). On AVX-512 a
// 16-lane pass costs what an 8-lane one does, and choosing between them per row was a
// branch that followed the chord's shape; with one kind of pass per row the compiler also
// keeps the backward's column sums in registers over the rows. Same bits: a pixel outside
// the chord has α < 1/255 (tiles.hpp), so the extra lanes blend nothing and add nothing. Rows
// the chord misses whole are still skipped, since evaluating them costs more than the branch.
template <typename Span>
[[gnu::always_inline]] inline void for_each_span(int h0, int h1, Span&& span) {
  if (DESPLAT_TILE_FULL_ROWS) {
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
    // A tile's Gaussians are in depth order, so their splats are scattered in memory: ask
    // for the one kSplatPrefetch entries ahead while this one is blended.
    if (k + kSplatPrefetch < end - begin) __builtin_prefetch(&out.splats[out.tile_entries[begin + k + kSplatPrefetch]]);
    const TileSplat& sp = out.splats[g];
    const float mx = sp.mx, my = sp.my;
    const float a = sp.conic[0], b = sp.conic[1], c = sp.conic[2];
    const float o = sp.opacity, z = sp.depth;
    const float cr = sp.rgb[0], cg = sp.rgb[1], cb = sp.rgb[2];
    int r0, r1, h0, h1;
    box_rows_in_tile(my, sp.ry, y0, rows, r0, r1);
    box_halves_in_tile(mx, sp.rx, x0, cols, h0, h1);
    if (h0 > h1) {
      out.entry_blank[begin + k] = 1;
      continue;
    }
    const RowChords chords(sp.chord, mx, x0, h0, h1);
    // Pixels that stopped at this entry, per column; summed once per entry rather than per row.
    alignas(64) int32_t finished[S] = {};
    alignas(64) int32_t row_h0[S], row_h1[S];
    chords.row_halves(my, y0, row_h0, row_h1);
    // Whether the chord reaches no row here; stored once after the rows (a byte store may
    // alias the pixel state, so one inside the loop would make the compiler reload it).
    bool blank = true;
    for (int r = r0; r <= r1; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const int row = r * S;
      const int rh0 = row_h0[r], rh1 = row_h1[r];
      if (rh0 > rh1) continue;
      blank = false;
      evaluated += (rh1 - rh0 + 1) * kHalfTile;  // halves, whatever the path (raster.hpp)
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
    out.entry_blank[begin + k] = blank;
    for (int col = 0; col < S; ++col) remaining -= finished[col];
  }

  for (int r = 0; r < rows; ++r) {
    const int64_t p0 = int64_t(y0 + r) * out.width + x0;
    const int row = r * S;
    float* color = &out.color[3 * p0];
#pragma omp simd
    for (int col = 0; col < cols; ++col)
      color[3 * col] = Cr[row + col], color[3 * col + 1] = Cg[row + col], color[3 * col + 2] = Cb[row + col];
#pragma omp simd
    for (int col = 0; col < cols; ++col) {
      out.alpha[p0 + col] = 1.0f - T[row + col];
      out.depth[p0 + col] = D[row + col];
      out.final_transmittance[p0 + col] = T[row + col];
      out.last_contributor[p0 + col] = last[row + col];
    }
  }
  return evaluated;
}

// Back-to-front walk of one tile: per (tile, Gaussian) entry, the gradient with respect to
// the Gaussian's 2D quantities from this tile's pixels (docs/METHOD.md §3). Training passes
// no depth gradient; without one (kWithDepth false) the depth term and its per-column sum are
// left out of the pixel loop instead of adding zeros (the kZ slot stays +0, as the zeros gave).
template <bool kWithDepth>
void backward_tile_walk(const TileGrid& grid, int tile, const RasterOutput& fw, const float* dC, const float* dA,
                        const float* dD, float* entry_grads) {
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
  // Pixels outside the image (a partial tile) keep these: nothing blended, no gradient.
  if (rows < S || cols < S)
    for (int j = 0; j < S * S; ++j) T[j] = 1, last[j] = -1, gr[j] = gg[j] = gb[j] = gd[j] = Q[j] = 0;
  // Row by row, one loop per input, so each is a plain (vectorizable) copy.
  int max_last = -1;
  // Per row, its last blended entry: a row whose pixels all stopped in front of entry k has
  // nothing to add for k (every lane's in_list would be 0), so the walk skips it. `last` does
  // not change during the walk, so this is one table per tile.
  alignas(64) int32_t row_last[S];
  std::fill_n(row_last, S, -1);
  for (int r = 0; r < rows; ++r) {
    const int64_t p0 = int64_t(y0 + r) * fw.width + x0;
    float *t = &T[r * S], *q = &Q[r * S], *cr = &gr[r * S], *cg = &gg[r * S], *cb = &gb[r * S], *cd = &gd[r * S];
    int32_t* l = &last[r * S];
    int32_t row_max = -1;
#pragma omp simd reduction(max : row_max)
    for (int col = 0; col < cols; ++col) {
      t[col] = fw.final_transmittance[p0 + col];
      l[col] = fw.last_contributor[p0 + col];
      row_max = std::max(row_max, l[col]);
    }
    row_last[r] = row_max;
    max_last = std::max(max_last, row_max);
    if (dC) {
#pragma omp simd
      for (int col = 0; col < cols; ++col)
        cr[col] = dC[3 * (p0 + col)], cg[col] = dC[3 * (p0 + col) + 1], cb[col] = dC[3 * (p0 + col) + 2];
    } else {
      std::fill_n(cr, cols, 0.0f), std::fill_n(cg, cols, 0.0f), std::fill_n(cb, cols, 0.0f);
    }
    if (dD)
      std::copy_n(&dD[p0], cols, cd);
    else
      std::fill_n(cd, cols, 0.0f);
    if (dA) {
#pragma omp simd
      for (int col = 0; col < cols; ++col) q[col] = t[col] * dA[p0 + col];
    } else {
      std::fill_n(q, cols, 0.0f);
    }
  }

  const int begin = fw.tile_offsets[tile], end = fw.tile_offsets[tile + 1];
  // Entries after the last blended one in every pixel get zero gradient.
  for (int e = begin + max_last + 1; e < end; ++e)
    std::fill_n(entry_grads + size_t(fw.record_of_entry[e]) * kEntrySlots, kEntrySlots, 0.0f);
  for (int k = max_last; k >= 0; --k) {
    float* record = entry_grads + size_t(fw.record_of_entry[begin + k]) * kEntrySlots;
    // An entry whose chord reaches no row of the tile (the forward's finding, with the same
    // box and chord arithmetic as below) would walk no row: its sums stay +0.
    if (fw.entry_blank[begin + k]) {
      std::fill_n(record, kEntrySlots, 0.0f);
      continue;
    }
    const int32_t g = fw.tile_entries[begin + k];
    if (k >= kSplatPrefetch) __builtin_prefetch(&fw.splats[fw.tile_entries[begin + k - kSplatPrefetch]]);
    const TileSplat& sp = fw.splats[g];
    const float mx = sp.mx, my = sp.my;
    const float a = sp.conic[0], b = sp.conic[1], c = sp.conic[2];
    const float o = sp.opacity, z = sp.depth;
    const float cr = sp.rgb[0], cg = sp.rgb[1], cb = sp.rgb[2];
    int r0, r1, h0, h1;
    box_rows_in_tile(my, sp.ry, y0, rows, r0, r1);
    box_halves_in_tile(mx, sp.rx, x0, cols, h0, h1);
    // Per-column partial sums, one lane per pixel column: elementwise updates vectorize,
    // and the lanes are summed in a fixed order afterwards (deterministic). Only the columns
    // the spans below write and sum_columns reads start at +0: the box's halves [h0, h1]
    // (h0 ≤ h1: the forward marked an entry without halves blank), or every column when a
    // span is a whole row.
    alignas(64) float acc[kEntrySlots][S];
    for (int q = 0; q < kEntrySlots; ++q)
      for_each_span(h0, h1, [&](auto width, int first) { std::fill_n(&acc[q][first], decltype(width)::value, 0.0f); });
    const RowChords chords(sp.chord, mx, x0, h0, h1);
    alignas(64) int32_t row_h0[S], row_h1[S];
    chords.row_halves(my, y0, row_h0, row_h1);
    // Whether any row was walked: an entry whose rows all stopped in front of it keeps its
    // sums at +0, which its record gets without the column sums.
    bool visited = false;
    for (int r = r0; r <= r1; ++r) {
      const float dy = my - (y0 + r + 0.5f);
      const int row = r * S;
      const int rh0 = row_h0[r], rh1 = row_h1[r];
      if (rh0 > rh1 || k > row_last[r]) continue;
      visited = true;
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
          const float dot =
              kWithDepth ? cr * gr[j] + cg * gg[j] + cb * gb[j] + z * gd[j] : cr * gr[j] + cg * gg[j] + cb * gb[j];
          const float d_alpha = t_before * dot + ra * Q[j];
          const float unclamped = o * vis <= kAlphaMax ? hit : 0.0f;
          const float d_sigma = -unclamped * d_alpha * o * vis;
          // (a·dx + b·dy) fused as it always compiled; the compiler no longer fuses it
          // on its own once a·dx is hoisted out of the row loop.
          const float gmx = d_sigma * madd(a, dx, b * dy);
          const float gmy = d_sigma * (b * dx + c * dy);
          acc[kR][col] += w * gr[j];
          acc[kG][col] += w * gg[j];
          acc[kB][col] += w * gb[j];
          if constexpr (kWithDepth) acc[kZ][col] += w * gd[j];
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
    // Columns outside the box's halves hold +0 (not visited, or on AVX-512 visited by lanes
    // that add only ±0 to +0), and adding +0 changes no sum: they are left out.
    if (visited)
      sum_columns(acc, h0 * kHalfTile, (h1 + 1) * kHalfTile, record);
    else
      std::fill_n(record, kEntrySlots, 0.0f);
  }
}

void backward_tile(const TileGrid& grid, int tile, const RasterOutput& fw, const float* dC, const float* dA,
                   const float* dD, float* entry_grads) {
  if (dD)
    backward_tile_walk<true>(grid, tile, fw, dC, dA, dD, entry_grads);
  else
    backward_tile_walk<false>(grid, tile, fw, dC, dA, dD, entry_grads);
}

}  // namespace

extern const TileKernels kTileKernels{&blend_tile, &backward_tile};

}  // namespace desplat::raster::DESPLAT_TILE_NS
