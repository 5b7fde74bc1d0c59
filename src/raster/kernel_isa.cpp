// Run-time choice of the pixel loops' instruction set (raster.hpp, KernelIsa).
#include <stdexcept>
#include <string>

#include "raster/tile_kernels.hpp"

namespace desplat {

bool cpu_supports(KernelIsa isa) {
  switch (isa) {
    case KernelIsa::Auto:
    case KernelIsa::Portable:
      return true;
#if DESPLAT_X86_KERNELS
    // __builtin_cpu_supports also checks that the OS saves the vector registers (XCR0).
    case KernelIsa::Avx2:
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case KernelIsa::Avx512:
      return cpu_supports(KernelIsa::Avx2) && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
             __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq");
#else
    case KernelIsa::Avx2:
    case KernelIsa::Avx512:
      return false;
#endif
  }
  return false;
}

KernelIsa resolve_kernel_isa(KernelIsa isa) {
  if (isa == KernelIsa::Auto) {
    for (KernelIsa widest : {KernelIsa::Avx512, KernelIsa::Avx2})
      if (cpu_supports(widest)) return widest;
    return KernelIsa::Portable;
  }
  if (!cpu_supports(isa))
    throw std::invalid_argument(std::string("kernel instruction set '") + kernel_isa_name(isa) +
                                "' is not supported by this CPU (or this build)");
  return isa;
}

const char* kernel_isa_name(KernelIsa isa) {
  switch (isa) {
    case KernelIsa::Auto:
      return "auto";
    case KernelIsa::Portable:
      return "portable";
    case KernelIsa::Avx2:
      return "avx2";
    case KernelIsa::Avx512:
      return "avx512";
  }
  return "?";
}

std::optional<KernelIsa> parse_kernel_isa(std::string_view name) {
  for (KernelIsa isa : {KernelIsa::Auto, KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512})
    if (name == kernel_isa_name(isa)) return isa;
  return std::nullopt;
}

namespace raster {

const TileKernels& tile_kernels(KernelIsa resolved) {
  switch (resolved) {
#if DESPLAT_X86_KERNELS
    case KernelIsa::Avx512:
      return avx512::kTileKernels;
    case KernelIsa::Avx2:
      return avx2::kTileKernels;
#endif
    case KernelIsa::Portable:
      return portable::kTileKernels;
    default:
      break;
  }
  throw std::logic_error(std::string("tile_kernels: no compiled path for '") + kernel_isa_name(resolved) + "'");
}

}  // namespace raster
}  // namespace desplat
