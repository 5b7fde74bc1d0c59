// CPU Gaussian splatting: forward rendering and its hand-written backward pass.
//
// Semantics follow gsplat 1.5's "classic" rasterizer exactly (docs/METHOD.md §3): EWA
// projection with a 0.3 px² blur, 3.33σ extents, 16×16 tiles with per-tile depth
// order, front-to-back blending with α = min(0.999, o·exp(−σ)), α < 1/255 skipped and
// a pixel finished once its transmittance would reach 1e-4.
//
// Data layout (chosen for a CPU):
//   * every per-Gaussian array is a structure of arrays, row-major [N, k];
//   * images are row-major [H, W, c] (channels interleaved), pixel (x, y) at y·W + x;
//   * binning produces one contiguous, depth-sorted work list per tile
//     (`tile_offsets`/`tile_entries`, CSR form); a tile is rasterized Gaussian by
//     Gaussian with the inner loop running over a row of up to 16 pixels held in
//     per-pixel arrays, restricted to the part of the tile inside the Gaussian's
//     3.33σ box (exact: outside the box α < 1/255);
//   * the backward pass writes one gradient record per (tile, Gaussian) entry and then
//     reduces each Gaussian's records in a fixed order, so outputs and gradients are
//     bit-identical for any number of threads, with no atomics anywhere.
//
// Thread safety: the functions are re-entrant; each call uses OpenMP with
// `RasterSettings::num_threads` threads. Outputs are owned by the caller and reused
// between calls (vectors are resized, not reallocated, when sizes repeat).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/core/gaussians.hpp"

namespace desplat {

// The instruction set the per-tile pixel loops (forward blending, backward per-pixel
// gradients) are compiled for; the rest of the rasterizer is built once for the build's
// target. Every path is compiled into the library and chosen at run time.
//   Auto      the widest path this CPU supports (Avx512 > Avx2 > Portable);
//   Portable  the build's baseline without AVX (with DESPLAT_NATIVE=OFF: SSE2 on x86-64),
//             no fused multiply–adds: runs on any CPU the build targets;
//   Avx2      8-lane AVX2 + FMA: a tile row is two vectors, one per 8-column half;
//   Avx512    AVX-512 F/VL/BW/DQ: a row the Gaussian covers in both halves is one
//             16-lane vector, a row it covers in one half an 8-lane one.
// AVX2 and AVX-512 compute every α, transmittance and stopping decision bit-identically
// (the falloff and exp spell out their fused multiply–adds) and agree in the blended sums
// and gradients to float rounding (the compiler may fuse other products differently). The
// portable path rounds those products separately, so it agrees with them to float rounding.
// A forward and its backward always run the same path (RasterOutput::isa).
enum class KernelIsa { Auto, Portable, Avx2, Avx512 };

// Whether this CPU (and OS) can run `isa`'s path; Auto and Portable always can.
bool cpu_supports(KernelIsa isa);
// Auto → the widest supported path; any other value is returned as is when supported.
// Throws std::invalid_argument naming the path when the CPU cannot run it.
KernelIsa resolve_kernel_isa(KernelIsa isa);
// "auto", "portable", "avx2", "avx512"; parse_kernel_isa is its inverse (nullopt otherwise).
const char* kernel_isa_name(KernelIsa isa);
std::optional<KernelIsa> parse_kernel_isa(std::string_view name);

struct RasterSettings {
  float near_plane = 0.01f;  // cull p.z <= near  [world units along the optical axis]
  float far_plane = 1e10f;   // cull p.z >= far
  float eps2d = 0.3f;        // isotropic blur added to every 2D covariance [px²]
  // SH degree used for this render (≤ the stored degree); -1 means "the stored one".
  int active_sh_degree = -1;
  int num_threads = 0;              // 0: OpenMP's default
  KernelIsa isa = KernelIsa::Auto;  // the pixel loops' instruction set (above)
};

constexpr int kTileSize = 16;

// What the pixel loops read of one Gaussian, packed into one 64-byte cache line: a tile entry
// then costs one line of a Gaussian visited in depth order (random ids) instead of one per
// per-Gaussian array. The chord shape is written by rasterize_project; the other fields are
// copies of RasterOutput's arrays, made by rasterize_blend after the colours are final (a
// caller may change rgb between rasterize_project and rasterize_blend).
struct alignas(64) TileSplat {
  float mx, my;          // means2d
  float conic[3];        // conics
  float opacity, depth;  // opacity, depths
  float rgb[3];          // rgb
  float chord[4];        // the ellipse's row chords within the blend box (src/raster/tiles.hpp,
                         // chord_shape); zero for an invisible Gaussian
  int32_t rx, ry;        // blend_radii
};
static_assert(sizeof(TileSplat) == 64);

// Everything the forward pass produces. The per-pixel and per-Gaussian results are
// the public outputs; the members under "saved for backward" are the state the
// backward pass needs and should be treated as opaque.
struct RasterOutput {
  int width = 0, height = 0;
  // Per pixel.
  std::vector<float> color;  // [H, W, 3] premultiplied C = Σ cᵢ αᵢ Tᵢ (no background)
  std::vector<float> alpha;  // [H, W]    accumulated alpha A = 1 − T_final
  std::vector<float> depth;  // [H, W]    expected depth Σ zᵢ αᵢ Tᵢ (not normalized)
  // Per Gaussian (entries of invisible Gaussians are zero).
  std::vector<float> means2d;    // [N, 2] projected center [px]
  std::vector<float> conics;     // [N, 3] (a, b, c) of the inverse 2D covariance
  std::vector<int32_t> radii;    // [N, 2] 3.33σ extent in x and y [px]; 0 if culled
                                 // (the screen size density control reads)
  std::vector<float> depths;     // [N]    camera-space z
  std::vector<uint8_t> visible;  // [N]    1 if the Gaussian touches at least one tile
  // Work done, for benchmarks: Gaussian–pixel pairs in the 8-column halves of each tile row
  // that a Gaussian's chord reaches (docs/METHOD.md §3), the pairs the AVX2 path evaluates.
  // The AVX-512 path evaluates each such row whole (16 lanes cost what 8 do there); the
  // count is the same on every path, so ns per pair compares builds and paths.
  int64_t evaluated_pairs = 0;

  // --- saved for backward ---
  std::vector<float> rgb;                  // [N, 3] color after SH / clamp
  std::vector<float> opacity;              // [N]    sigmoid(logit)
  std::vector<float> scales;               // [N, 3] exp(log_scales), world units
  std::vector<uint8_t> color_clamped;      // [N, 3] 1 where the color clamp was active
  std::vector<int32_t> blend_radii;        // [N, 2] the extent [px] in which α can reach 1/255
                                           // (≤ radii; opacity-dependent): tiles and rows visited
  std::vector<TileSplat> splats;           // [N] the above and the row chords, packed for the
                                           // pixel loops (complete for the Gaussians listed in
                                           // a tile only)
  std::vector<int32_t> tile_offsets;       // [tiles + 1] CSR offsets into tile_entries
  std::vector<int32_t> tile_entries;       // [E] Gaussian ids, depth-sorted per tile
  std::vector<int32_t> gaussian_offsets;   // [N + 1] each Gaussian's first gradient record
  std::vector<int32_t> record_of_entry;    // [E] per tile entry, its gradient record: records
                                           // are grouped by Gaussian, each group in tile order
  std::vector<uint8_t> entry_blank;        // [E] 1 where the Gaussian's box reaches the tile but
                                           // its chord no pixel row there (nothing to blend or
                                           // to differentiate); set for the entries the forward
                                           // walked, which include every one the backward walks
  std::vector<float> final_transmittance;  // [H, W]
  std::vector<int32_t> last_contributor;   // [H, W] index within the tile list, −1: none
  // The pixel-loop path rasterize_blend ran (resolved, never Auto); the backward runs the
  // same one, so it recomputes α bit-identically whatever its own settings say.
  KernelIsa isa = KernelIsa::Portable;
};

struct RasterGradients {
  std::vector<float> means;           // [N, 3]
  std::vector<float> log_scales;      // [N, 3]
  std::vector<float> quats;           // [N, 4]
  std::vector<float> opacity_logits;  // [N]
  std::vector<float> colors;          // same shape as GaussianView::colors
  // [N, F] ∂L/∂GaussianSet::features. The rasterizer leaves it alone (it never reads the
  // features); the appearance model's backward fills it.
  std::vector<float> features;
  // [N, 3] ∂L/∂(the colour each Gaussian was blended with, RasterOutput::rgb), before the
  // colour clamp's and rgb_scale's chain rule: what a caller that changed the colours between
  // rasterize_project and rasterize_blend needs for its own backward pass.
  std::vector<float> rgb;
  std::vector<float> means2d;  // [N, 2] ∂L/∂μ2d (summed over pixels)
  // Densification statistic (docs/METHOD.md §3): per Gaussian, the 2-norm of
  // (Σ_pixels |∂L/∂μ2d.x|, Σ_pixels |∂L/∂μ2d.y|) [loss units per px].
  std::vector<float> absgrad;  // [N]

  // Scratch reused between calls: one gradient record per tile entry.
  std::vector<float> entry_scratch;
};

// Renders `gaussians` seen from `camera`. Throws std::invalid_argument for bad input
// (see GaussianView::validate, Camera::validate, active SH degree out of range).
// rasterize_forward = rasterize_project, then rasterize_blend.
void rasterize_forward(const GaussianView& gaussians, const Camera& camera, const RasterSettings& settings,
                       RasterOutput& out);

// The forward pass in two stages, for a caller that changes the colours of the visible
// Gaussians in between (the appearance model, docs/METHOD.md §10). rasterize_project fills
// every per-Gaussian output (visible, means2d, conics, radii, depths, opacity, rgb = the colour
// after SH and clamp); rasterize_blend bins the visible Gaussians and blends them with
// out.rgb as it finds it. `camera` and `settings` must be the same for both.
void rasterize_project(const GaussianView& gaussians, const Camera& camera, const RasterSettings& settings,
                       RasterOutput& out);
void rasterize_blend(const Camera& camera, const RasterSettings& settings, RasterOutput& out);

// Gradients of a scalar loss L given ∂L/∂color [H,W,3], ∂L/∂alpha [H,W] and
// ∂L/∂depth [H,W]; an empty span means zero. `forward` must be the result of
// rasterize_forward with the same gaussians, camera and settings.
// `rgb_scale` [N, 3] or empty (= 1): when the caller replaced out.rgb between the stages by a
// colour c̃ whose derivative with respect to the SH colour c is diagonal, ∂c̃/∂c per Gaussian and
// channel; the colour gradients are then ∂L/∂c = rgb_scale ⊙ ∂L/∂c̃. grads.rgb holds ∂L/∂c̃.
void rasterize_backward(const GaussianView& gaussians, const Camera& camera, const RasterSettings& settings,
                        const RasterOutput& forward, std::span<const float> dL_dcolor, std::span<const float> dL_dalpha,
                        std::span<const float> dL_ddepth, RasterGradients& grads,
                        std::span<const float> rgb_scale = {});

// Per Gaussian, its blend weight summed over the render's pixels, Σ_p αᵢ(p)·Tᵢ(p) [px]: how
// much of the image it makes (a fully opaque, unoccluded Gaussian covering k pixels: ≈ k).
// For each pixel the weights of all Gaussians add up to out.alpha. `out` must come from
// rasterize_forward (or rasterize_blend); [N], zero for invisible Gaussians. One thread: for
// density control on small layers (the distractors), not for every step.
std::vector<double> blend_weights(const RasterOutput& out);

}  // namespace desplat
