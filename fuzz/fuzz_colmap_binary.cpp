// libFuzzer harness for one COLMAP binary reader, chosen at build time by DESPLAT_FUZZ_FILE
// ("cameras.bin", "images.bin" or "points3D.bin"). The input becomes that file; the other two
// come from a small valid model, so read_model_binary parses the input and then runs the
// whole-model checks on it.
//
// Contract checked: read_model_binary returns or throws colmap::ColmapError; anything else
// (another exception, a crash, a sanitizer report, a hang, a huge allocation) is a finding.
// When it returns, writing the model and reading it back must reproduce it: the rewritten
// files are a fixed point of write(read(.)).
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "desplat/io/colmap.hpp"
#include "fuzz_common.hpp"

#ifndef DESPLAT_FUZZ_FILE
#error "define DESPLAT_FUZZ_FILE as the file this harness fuzzes"
#endif

namespace {

using namespace desplat;

struct Scene {
  fuzz::ScratchDir scratch{"colmap"};
  std::filesystem::path input_dir = scratch.path() / "in", rewrite_dir = scratch.path() / "out";

  Scene() { colmap::write_model_binary(fuzz::small_model(), input_dir); }
};

Scene& scene() {
  static Scene s;
  return s;
}

// write(read(input)) gives canonical files; reading and writing those again must not change
// a byte (a difference means the reader and writer disagree about some value).
void check_round_trip(const colmap::Model& model) {
  Scene& s = scene();
  colmap::write_model_binary(model, s.rewrite_dir);
  const colmap::ModelPaths first = colmap::ModelPaths::binary(s.rewrite_dir);
  const std::string cameras = fuzz::read_all(first.cameras), images = fuzz::read_all(first.images),
                    points = fuzz::read_all(first.points);
  colmap::write_model_binary(colmap::read_model_binary(s.rewrite_dir), s.rewrite_dir);
  if (fuzz::read_all(first.cameras) != cameras || fuzz::read_all(first.images) != images ||
      fuzz::read_all(first.points) != points) {
    std::fprintf(stderr, "finding: COLMAP binary write/read/write is not a fixed point\n");
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Scene& s = scene();
  fuzz::write_input(s.input_dir / DESPLAT_FUZZ_FILE, data, size);
  colmap::Model model;
  try {
    model = colmap::read_model_binary(s.input_dir);
  } catch (const colmap::ColmapError&) {
    return 0;  // the documented way to refuse an input
  }
  check_round_trip(model);
  return 0;
}
