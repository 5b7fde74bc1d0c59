// The photometric loss's cost: 0.8·L1 + 0.2·(1 − SSIM) and its gradient (photometric_loss)
// on one training image, 500×375 (the synthetic benchmark's size) and 540×960 (the fox at
// ½ resolution), on 1 and 2 threads. The images are random: the loss does the same work
// whatever the pixels hold.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <random>
#include <vector>

#include "desplat/train/loss.hpp"

namespace {

using namespace desplat;

void BM_PhotometricLoss(benchmark::State& state) {
  const int width = int(state.range(0)), height = int(state.range(1)), threads = int(state.range(2));
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  std::vector<float> render(size_t(width) * height * 3), target(render.size()), d_render(render.size());
  for (float& v : render) v = uniform(rng);
  for (float& v : target) v = uniform(rng);
  omp_set_num_threads(threads);
  for (auto _ : state) {
    const PhotometricLoss loss = photometric_loss(render, target, width, height, 0.2f, d_render);
    benchmark::DoNotOptimize(loss);
  }
  state.counters["pixels"] = double(width) * height;
}
BENCHMARK(BM_PhotometricLoss)
    ->Args({500, 375, 1})
    ->Args({500, 375, 2})
    ->Args({540, 960, 1})
    ->Args({540, 960, 2})
    ->ArgNames({"width", "height", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
