// libFuzzer harness for the 3DGS PLY reader.
//
// Contract checked: read_gaussian_ply returns or throws PlyError; anything else (another
// exception, a crash, a sanitizer report, a hang, a huge allocation) is a finding. When it
// returns, the set must be consistent, and writing it (identity normalization) and reading it
// back must give the same bits.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "desplat/io/ply.hpp"
#include "fuzz_common.hpp"

namespace {

using namespace desplat;

struct Scene {
  fuzz::ScratchDir scratch{"ply"};
  std::filesystem::path input = scratch.path() / "in.ply", rewritten = scratch.path() / "out.ply";
};

Scene& scene() {
  static Scene s;
  return s;
}

[[noreturn]] void finding(const char* what) {
  std::fprintf(stderr, "finding: %s\n", what);
  std::abort();
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void check_round_trip(const GaussianSet& g) {
  try {
    g.view().validate();
  } catch (const std::invalid_argument&) {
    finding("the reader returned an inconsistent GaussianSet");
  }
  Scene& s = scene();
  write_gaussian_ply(s.rewritten, g);  // a PlyError here escapes: the writer refused what we read
  const GaussianSet r = read_gaussian_ply(s.rewritten);
  if (r.sh_degree != g.sh_degree || r.color_mode != g.color_mode || !same_bits(r.means, g.means) ||
      !same_bits(r.log_scales, g.log_scales) || !same_bits(r.quats, g.quats) ||
      !same_bits(r.opacity_logits, g.opacity_logits) || !same_bits(r.colors, g.colors))
    finding("PLY write/read changed the Gaussians");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Scene& s = scene();
  fuzz::write_input(s.input, data, size);
  GaussianSet g;
  try {
    g = read_gaussian_ply(s.input);
  } catch (const PlyError&) {
    return 0;  // the documented way to refuse an input
  }
  check_round_trip(g);
  return 0;
}
