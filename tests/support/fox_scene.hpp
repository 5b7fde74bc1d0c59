// Where the tests find the real fox capture (images/ + sparse/0/ written by COLMAP): the
// environment variable DESPLAT_FOX_DIR when set, else the CMake cache variable DESPLAT_FOX_DIR
// (default: ../shared/data/fox beside the source tree). Tests that need it skip when absent.
#pragma once

#include <cstdlib>
#include <filesystem>

#ifndef DESPLAT_FOX_DIR_DEFAULT
#error "tests/CMakeLists.txt defines DESPLAT_FOX_DIR_DEFAULT for every test"
#endif

namespace desplat::testing {

// Absolute and without "..", as the scene loader reports paths.
inline std::filesystem::path fox_dir() {
  const char* env = std::getenv("DESPLAT_FOX_DIR");
  const std::filesystem::path dir = env != nullptr && *env != '\0' ? env : DESPLAT_FOX_DIR_DEFAULT;
  return std::filesystem::weakly_canonical(std::filesystem::absolute(dir));
}

inline bool fox_available() { return std::filesystem::exists(fox_dir() / "sparse" / "0"); }

}  // namespace desplat::testing
