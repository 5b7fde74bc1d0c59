// The appearance model's cost (docs/METHOD.md §10): AppearancePass forward and backward over
// N visible static Gaussians (SH degree 3, z_i of 24, the default MLP of 2 × 32), as in one
// training step, on 1 and 2 threads. At fox ¼ a full-size step sees about 26,000-40,000
// Gaussians, and the colours of 54–57 % of them reach a pixel (the rest get no gradient).
#include <benchmark/benchmark.h>

#include <random>

#include "desplat/train/appearance.hpp"

namespace {

using namespace desplat;

struct Setup {
  AppearanceModel model;
  GaussianSet g;
  RasterOutput fw;
  RasterGradients grads;
  std::vector<float> rgb;  // the colours after SH, restored before each forward
  // `reached`: the percentage of rows whose colour gets a gradient (the others' is zero).
  Setup(size_t n, int reached) {
    AppearanceSettings s;
    s.enabled = true;
    model = AppearanceModel(s, 4, 7);
    std::mt19937 rng(5);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    for (float& w : model.mlp) w = 0.2f * normal(rng);  // a trained-looking net, not the zero start
    g.color_mode = ColorMode::SphericalHarmonics;
    g.sh_degree = 3;
    g.feature_dim = s.feature_dim();
    g.resize(n);
    for (float& c : g.colors) c = 0.3f * normal(rng);
    for (float& f : g.features) f = normal(rng);
    fw.visible.assign(n, 1);
    rgb.resize(3 * n);
    for (float& c : rgb) c = 0.5f + 0.2f * normal(rng);
    grads.rgb.resize(3 * n);
    for (float& d : grads.rgb) d = 1e-3f * normal(rng);
    for (size_t i = 0; i < n; ++i)  // spread over the rows, as hidden Gaussians are
      if (int(i * 37 % 100) >= reached) grads.rgb[3 * i] = grads.rgb[3 * i + 1] = grads.rgb[3 * i + 2] = 0.0f;
    grads.colors.assign(g.colors.size(), 0.0f);
  }
};

// range(2): 1 = forward and backward (a training step), 0 = forward alone (a render);
// range(3): the percentage of rows whose colour reached a pixel.
void BM_Appearance(benchmark::State& state) {
  Setup s(size_t(state.range(0)), int(state.range(3)));
  const int threads = int(state.range(1));
  const bool backward = state.range(2) != 0;
  AppearancePass pass;
  for (auto _ : state) {
    s.fw.rgb = s.rgb;
    pass.forward(s.model, s.model.embedding(1), s.g, s.fw, threads);
    if (backward) pass.backward(s.model, s.model.embedding(1), s.g, s.grads, threads);
    benchmark::DoNotOptimize(s.fw.rgb.data());
    benchmark::DoNotOptimize(pass.d_mlp.data());
  }
  state.counters["gaussians"] = double(state.range(0));
}
BENCHMARK(BM_Appearance)
    ->Args({40000, 1, 1, 100})
    ->Args({40000, 2, 1, 100})
    ->Args({40000, 1, 1, 55})
    ->Args({40000, 2, 1, 55})
    ->Args({40000, 1, 0, 100})
    ->Args({40000, 2, 0, 100})
    ->ArgNames({"visible", "threads", "backward", "reached"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
