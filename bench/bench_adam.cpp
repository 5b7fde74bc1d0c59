// The optimizer's cost: one Adam step (TrainableGaussians::adam_update) over N Gaussians
// with SH degree 3, as late in a run (every band trained, 59 floats per Gaussian), on 1 and
// 2 threads. `visible` < 100 updates only that share of the rows (selective Adam, rows
// picked at random); 100 is the default dense update. `sh_floats` is how many of the 48
// colour floats per Gaussian are trained: 3, 12, 27 at SH degrees 0–2, early in a run.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <random>

#include "desplat/train/trainable.hpp"

namespace {

using namespace desplat;

void BM_AdamUpdate(benchmark::State& state) {
  const size_t n = size_t(state.range(0));
  const int visible_percent = int(state.range(1));
  const int threads = int(state.range(2));
  const int sh_floats = int(state.range(3));
  std::mt19937 rng(3);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  GaussianSet g;
  g.color_mode = ColorMode::SphericalHarmonics;
  g.sh_degree = 3;
  g.resize(n);
  RasterGradients grads;
  for (int k = 0; k < kParamGroups; ++k) {
    for (float& x : g.*kParamGroupTable[k].values) x = normal(rng);
    std::vector<float>& d = grads.*kParamGroupTable[k].grads;
    d.resize((g.*kParamGroupTable[k].values).size());
    for (float& x : d) x = 0.01f * normal(rng);
  }
  TrainableGaussians t(std::move(g));
  std::vector<uint8_t> rows;
  if (visible_percent < 100) {
    std::bernoulli_distribution seen(visible_percent / 100.0);
    rows.resize(n);
    for (uint8_t& r : rows) r = uint8_t(seen(rng));
  }
  omp_set_num_threads(threads);
  for (auto _ : state) t.adam_update(grads, LearningRates{}, AdamSettings{}, sh_floats, rows);
  state.counters["gaussians"] = double(n);
}
BENCHMARK(BM_AdamUpdate)
    ->Args({72000, 100, 1, 48})
    ->Args({72000, 100, 2, 48})
    ->Args({72000, 70, 1, 48})
    ->Args({72000, 70, 2, 48})
    ->Args({30000, 100, 1, 3})
    ->Args({30000, 100, 1, 12})
    ->Args({30000, 100, 1, 27})
    ->Args({30000, 100, 1, 48})
    ->ArgNames({"gaussians", "visible", "threads", "sh_floats"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
