// The per-tile pixel loops, compiled once per instruction set (tile_kernels.inl, included
// by tile_kernels_<isa>.cpp with that file's compiler flags) and picked at run time.
#pragma once

#include <cstdint>

#include "desplat/raster/raster.hpp"
#include "raster/tiles.hpp"

namespace desplat::raster {

// Per (tile, Gaussian) entry, the gradient with respect to the Gaussian's 2D
// quantities from that tile's pixels: kEntrySlots floats in this order.
enum EntrySlot { kR, kG, kB, kZ, kO, kA, kB2, kC, kMx, kMy, kAbsX, kAbsY, kEntrySlots };

struct TileKernels {
  // Front-to-back blending of one tile of `out` (binned by rasterize_blend); writes the
  // tile's pixels and returns the Gaussian–pixel pairs evaluated.
  int64_t (*blend_tile)(const TileGrid& grid, int tile, RasterOutput& out);
  // Back-to-front walk of one tile: one kEntrySlots record per tile entry in entry_grads, at
  // the entry's record_of_entry (grouped by Gaussian, so each Gaussian's sum reads them in a run).
  // dC [H,W,3], dA and dD [H,W] may be null (zero).
  void (*backward_tile)(const TileGrid& grid, int tile, const RasterOutput& fw, const float* dC, const float* dA,
                        const float* dD, float* entry_grads);
};

namespace portable {
extern const TileKernels kTileKernels;
}
#if DESPLAT_X86_KERNELS
namespace avx2 {
extern const TileKernels kTileKernels;
}
namespace avx512 {
extern const TileKernels kTileKernels;
}
#endif

// The kernels of a resolved path (not Auto); throws std::logic_error for a path this build
// did not compile.
const TileKernels& tile_kernels(KernelIsa resolved);

}  // namespace desplat::raster
