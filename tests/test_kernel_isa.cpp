// The pixel loops' instruction-set paths (raster.hpp, KernelIsa): which the CPU can run,
// read independently from /proc/cpuinfo; that the paths agree with each other where the
// header says they do (bit for bit in α, transmittance and stopping; to float rounding
// elsewhere); that each is deterministic across thread counts; and that the backward pass
// follows the forward's path. Each path against the double reference and the Jet
// gradients: test_forward.cpp and test_backward.cpp, run once per path.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <set>
#include <sstream>

#include "desplat/raster/raster.hpp"
#include "support/scenes.hpp"

namespace desplat::test {
namespace {

constexpr KernelIsa kPaths[] = {KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512};

// The CPU's feature flags as the kernel reports them (first "flags" line), empty off Linux/x86.
std::set<std::string> cpuinfo_flags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) {
      std::istringstream words(line.substr(line.find(':') + 1));
      return {std::istream_iterator<std::string>(words), std::istream_iterator<std::string>()};
    }
  return {};
}

TEST(KernelIsa, SupportMatchesTheCpuFlags) {
  const std::set<std::string> flags = cpuinfo_flags();
  if (flags.empty()) GTEST_SKIP() << "no /proc/cpuinfo flags to compare with";
  auto has = [&](std::initializer_list<const char*> names) {
    for (const char* n : names)
      if (!flags.count(n)) return false;
    return true;
  };
  const bool avx2 = has({"avx2", "fma"});
  const bool avx512 = avx2 && has({"avx512f", "avx512vl", "avx512bw", "avx512dq"});
  EXPECT_TRUE(cpu_supports(KernelIsa::Portable));
  EXPECT_EQ(cpu_supports(KernelIsa::Avx2), avx2);
  EXPECT_EQ(cpu_supports(KernelIsa::Avx512), avx512);
  EXPECT_EQ(resolve_kernel_isa(KernelIsa::Auto), avx512 ? KernelIsa::Avx512
                                                 : avx2 ? KernelIsa::Avx2
                                                        : KernelIsa::Portable);
}

TEST(KernelIsa, NamesRoundTripAndUnknownOnesAreRefused) {
  for (KernelIsa isa : {KernelIsa::Auto, KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512})
    EXPECT_EQ(parse_kernel_isa(kernel_isa_name(isa)), isa);
  EXPECT_EQ(parse_kernel_isa("sse4"), std::nullopt);
  EXPECT_EQ(parse_kernel_isa("AVX2"), std::nullopt);
  EXPECT_EQ(parse_kernel_isa(""), std::nullopt);
}

TEST(KernelIsa, AnUnsupportedPathIsAnErrorNamingIt) {
  int unsupported = 0;
  for (KernelIsa isa : kPaths) {
    if (cpu_supports(isa)) {
      EXPECT_EQ(resolve_kernel_isa(isa), isa);
      continue;
    }
    ++unsupported;
    try {
      resolve_kernel_isa(isa);
      ADD_FAILURE() << kernel_isa_name(isa) << " resolved on a CPU without it";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(kernel_isa_name(isa)), std::string::npos) << e.what();
    }
  }
  if (unsupported == 0) GTEST_SKIP() << "this CPU runs every path; nothing to refuse";
}

struct Render {
  RasterOutput out;
  RasterGradients grads;
};

// A busy scene (early termination and the α clamp both happen), rendered and
// differentiated with one path.
class IsaScene {
 public:
  IsaScene() : rng_(2024), cam_(random_camera(rng_, 131, 97, 110)) {
    SceneSpec spec;
    spec.count = 2500;
    spec.log_scale_min = -3.5f;
    spec.log_scale_max = -1.2f;
    spec.logit_max = 8.0f;
    g_ = random_gaussians(rng_, spec);
    std::normal_distribution<float> n(0, 1);
    const size_t pixels = size_t(cam_.width) * cam_.height;
    for (auto* v : {&wC_, &wA_, &wD_}) {
      v->resize((v == &wC_ ? 3 : 1) * pixels);
      for (float& x : *v) x = n(rng_);
    }
  }
  Render run(KernelIsa forward_isa, KernelIsa backward_isa, int threads) const {
    Render r;
    RasterSettings s;
    s.num_threads = threads;
    s.isa = forward_isa;
    rasterize_forward(g_.view(), cam_, s, r.out);
    s.isa = backward_isa;
    rasterize_backward(g_.view(), cam_, s, r.out, wC_, wA_, wD_, r.grads);
    return r;
  }

 private:
  std::mt19937 rng_;
  Camera cam_;
  GaussianSet g_;
  std::vector<float> wC_, wA_, wD_;
};

// Largest |a − b| over the vector, relative to the largest |b|.
double relative_gap(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double gap = 0, scale = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    gap = std::max(gap, std::abs(double(a[i]) - b[i]));
    scale = std::max(scale, std::abs(double(b[i])));
  }
  return scale > 0 ? gap / scale : gap;
}

TEST(KernelIsa, Avx2AndAvx512AgreeBitForBitInAlphaAndStopping) {
  if (!cpu_supports(KernelIsa::Avx512)) GTEST_SKIP() << "no AVX-512 on this CPU";
  const IsaScene scene;
  const Render a = scene.run(KernelIsa::Avx2, KernelIsa::Avx2, 2);
  const Render b = scene.run(KernelIsa::Avx512, KernelIsa::Avx512, 2);
  EXPECT_EQ(a.out.isa, KernelIsa::Avx2);
  EXPECT_EQ(b.out.isa, KernelIsa::Avx512);
  // Transmittance and the stopping index come from the same fused operations on both.
  EXPECT_EQ(a.out.final_transmittance, b.out.final_transmittance);
  EXPECT_EQ(a.out.last_contributor, b.out.last_contributor);
  EXPECT_EQ(a.out.alpha, b.out.alpha);
  // Colour, depth and gradients to float rounding (the compiler may fuse differently);
  // each path is also held to the double reference in test_forward / test_backward.
  EXPECT_LT(relative_gap(b.out.color, a.out.color), 1e-6);
  EXPECT_LT(relative_gap(b.out.depth, a.out.depth), 1e-6);
  EXPECT_LT(relative_gap(b.grads.means, a.grads.means), 1e-5);
  EXPECT_LT(relative_gap(b.grads.log_scales, a.grads.log_scales), 1e-5);
  EXPECT_LT(relative_gap(b.grads.opacity_logits, a.grads.opacity_logits), 1e-5);
  EXPECT_LT(relative_gap(b.grads.colors, a.grads.colors), 1e-5);
  // The scene exercises early termination (pixels stop before their list ends).
  size_t stopped = 0;
  for (float t : a.out.final_transmittance) stopped += t < 1e-3f;
  EXPECT_GT(stopped, a.out.final_transmittance.size() / 20);
}

TEST(KernelIsa, PortableAgreesWithTheWidestPathToFloatRounding) {
  const KernelIsa widest = resolve_kernel_isa(KernelIsa::Auto);
  if (widest == KernelIsa::Portable) GTEST_SKIP() << "only the portable path runs here";
  const IsaScene scene;
  const Render p = scene.run(KernelIsa::Portable, KernelIsa::Portable, 2);
  const Render w = scene.run(widest, widest, 2);
  EXPECT_EQ(p.out.isa, KernelIsa::Portable);
  EXPECT_LT(relative_gap(p.out.color, w.out.color), 2e-5);
  EXPECT_LT(relative_gap(p.out.alpha, w.out.alpha), 2e-5);
  EXPECT_LT(relative_gap(p.grads.means, w.grads.means), 1e-3);
  EXPECT_LT(relative_gap(p.grads.colors, w.grads.colors), 1e-3);
}

TEST(KernelIsa, EachPathIsBitIdenticalForOneAndTwoThreads) {
  const IsaScene scene;
  for (KernelIsa isa : kPaths) {
    if (!cpu_supports(isa)) continue;
    const Render one = scene.run(isa, isa, 1);
    const Render two = scene.run(isa, isa, 2);
    EXPECT_EQ(one.out.color, two.out.color) << kernel_isa_name(isa);
    EXPECT_EQ(one.out.depth, two.out.depth) << kernel_isa_name(isa);
    EXPECT_EQ(one.grads.means, two.grads.means) << kernel_isa_name(isa);
    EXPECT_EQ(one.grads.quats, two.grads.quats) << kernel_isa_name(isa);
    EXPECT_EQ(one.grads.colors, two.grads.colors) << kernel_isa_name(isa);
    EXPECT_EQ(one.grads.absgrad, two.grads.absgrad) << kernel_isa_name(isa);
  }
}

TEST(KernelIsa, TheBackwardRunsTheForwardsPath) {
  const KernelIsa widest = resolve_kernel_isa(KernelIsa::Auto);
  if (widest == KernelIsa::Portable) GTEST_SKIP() << "only the portable path runs here";
  const IsaScene scene;
  // Forward on the portable path, backward asked for the widest: the gradients must be the
  // portable path's own, since α is recomputed with the forward's rounding.
  const Render mixed = scene.run(KernelIsa::Portable, widest, 2);
  const Render own = scene.run(KernelIsa::Portable, KernelIsa::Portable, 2);
  const Render wide = scene.run(widest, widest, 2);
  EXPECT_EQ(mixed.grads.means, own.grads.means);
  EXPECT_EQ(mixed.grads.colors, own.grads.colors);
  EXPECT_NE(own.grads.means, wide.grads.means) << "the paths should differ in rounding somewhere";
}

}  // namespace
}  // namespace desplat::test
