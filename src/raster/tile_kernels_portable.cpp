// The pixel loops (tile_kernels.inl) compiled for the portable path; its compiler flags are
// set in src/CMakeLists.txt.
#define DESPLAT_TILE_NS portable
#define DESPLAT_TILE_FULL_ROWS 0
#include "raster/tile_kernels.inl"
