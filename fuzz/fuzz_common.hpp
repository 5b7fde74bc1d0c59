// Shared pieces of the libFuzzer harnesses: a scratch directory in memory (/dev/shm) where
// each input is written, since the readers take paths, and the small valid COLMAP model that
// serves both as the harnesses' companion files and as a corpus seed.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "desplat/io/colmap.hpp"

namespace desplat::fuzz {

// A per-process directory, removed at normal exit. On a crash it stays behind (small).
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& name) {
    const std::filesystem::path base =
        std::filesystem::is_directory("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
    dir_ = base / ("desplat-fuzz-" + name + "-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

// A failure to set up the input is the harness's problem, not a finding: stop loudly.
inline void write_input(const std::filesystem::path& path, const std::uint8_t* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) {
    std::fprintf(stderr, "harness: cannot write %s\n", path.c_str());
    std::abort();
  }
}

inline std::string read_all(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Two cameras, two images and two points whose tracks and observations agree: every
// cross-file check of validate_model has something to look at.
inline colmap::Model small_model() {
  using namespace colmap;
  Model m;
  m.cameras[1] = {1, CameraModelId::Pinhole, 640, 480, {500, 500, 320, 240}};
  m.cameras[2] = {2, CameraModelId::OpenCV, 800, 600, {600, 610, 400, 300, 0.01, -0.02, 0.001, 0.002}};
  m.images[1] = {1, {1, 0, 0, 0}, {0, 0, 0}, 1, "a.png", {{10, 20, 1}, {30, 40, kNoPoint3D}, {50, 60, 2}}};
  m.images[2] = {2, {0.9, 0.1, 0.2, 0.3}, {1, 2, 3}, 2, "dir/b.png", {{1.5, 2.5, 1}, {3.5, 4.5, 2}}};
  m.points[1] = {1, {0, 0, 5}, {255, 128, 0}, 0.5, {{1, 0}, {2, 0}}};
  m.points[2] = {2, {1, -1, 6}, {0, 64, 255}, 0.25, {{1, 2}, {2, 1}}};
  return m;
}

}  // namespace desplat::fuzz
