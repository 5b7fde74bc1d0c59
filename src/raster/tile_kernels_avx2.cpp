// The pixel loops (tile_kernels.inl) compiled for the avx2 path; its compiler flags are
// set in src/CMakeLists.txt.
#define DESPLAT_TILE_NS avx2
#define DESPLAT_TILE_FULL_ROWS 0
#include "raster/tile_kernels.inl"
