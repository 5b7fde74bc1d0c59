// The pixel loops (tile_kernels.inl) compiled for the avx512 path; its compiler flags are
// set in src/CMakeLists.txt.
#define DESPLAT_TILE_NS avx512
#define DESPLAT_TILE_FULL_ROWS 1
#include "raster/tile_kernels.inl"
