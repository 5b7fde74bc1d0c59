// The camera-path cull's cost (train/free_space.hpp): on_camera_path over N Gaussian centres
// for a capture of V photos on a circle of radius 1 around a scene in the unit ball (the
// normalized frame, docs/METHOD.md §1), as each static refinement (every 100 steps) runs it.
// Compare with bench_adam's BM_AdamUpdate, which every step runs over the same N. The last
// argument turns the blind-gap rule on (1, the default) or off (0, the tube alone).
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cmath>
#include <random>

#include "desplat/train/free_space.hpp"

namespace {

using namespace desplat;

void BM_CameraPathCull(benchmark::State& state) {
  const size_t n = size_t(state.range(0));
  const int views = int(state.range(1));
  omp_set_num_threads(int(state.range(2)));
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<Camera> cams;
  for (int v = 0; v < views; ++v) {
    // Looking at the origin from (sin a, 0, −cos a): rows of R_cw are right, down, forward.
    const float a = 6.2831853f * v / views, s = std::sin(a), c = std::cos(a);
    Camera cam;
    cam.width = cam.height = 100;
    cam.fx = cam.fy = 100, cam.cx = cam.cy = 50;
    cam.R_cw = {c, 0, s, 0, 1, 0, -s, 0, c};
    cam.t_cw = {0, 0, 1};
    cams.push_back(cam);
  }
  std::vector<std::array<float, 3>> points(2000);
  for (auto& p : points) p = {0.5f * u(rng), 0.5f * u(rng), 0.5f * u(rng)};
  CameraPathSettings settings;
  if (state.range(3) == 0) settings.blind_gap = 0;
  const CameraPath path = camera_path(cams, points, settings);
  std::vector<float> means(3 * n);
  for (float& x : means) x = u(rng);
  for (auto _ : state) benchmark::DoNotOptimize(on_camera_path(path, means));
  state.counters["segments"] = double(path.from.size());
}
BENCHMARK(BM_CameraPathCull)
    ->Args({72000, 43, 1, 1})
    ->Args({72000, 43, 1, 0})
    ->Args({72000, 43, 2, 1})
    ->Args({72000, 300, 1, 1})
    ->Args({72000, 300, 1, 0})
    ->ArgNames({"gaussians", "views", "threads", "blind_gap"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
