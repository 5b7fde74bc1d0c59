// Rasterizer throughput: forward, and forward + backward, on 1 and 2 threads.
//   * frustum scenes: N random Gaussians (N = 100k, 500k) spread through the view
//     frustum of a 512×384 camera, depths 2–10, world sizes 0.005–0.035 (about
//     0.2–7 px on screen), SH degree 3;
//   * fox: the 12,421-point COLMAP model of ../shared/data/fox initialized as in
//     training (docs/METHOD.md §5), seen from its first camera at 540×960;
//   * trained fox: DESPLAT_BENCH_PLY (a desplat_train point_cloud.ply of the fox) from
//     the same camera: the workload of a late training step;
//   * trained fox at 270×480 (½ size): the full-resolution steps of the speed benchmark's command
//     (`desplat_train --data fox --downscale 2`);
//   * trained fox at 135×240 (the same camera at ¼ size): few pixels per Gaussian, so the
//     per-Gaussian stages (projection, binning, sorting, the backward's per-Gaussian
//     half) weigh as in the low-resolution steps of a training run.
// Counters: pairs = Gaussian–pixel pairs per call in the row halves the chords reach
// (RasterOutput::evaluated_pairs, the same count on every path);
// time_per_pair = wall time per such pair. Each runs once per pixel-loop path
// (isa: 1 portable, 2 AVX2, 3 AVX-512; raster.hpp, KernelIsa), skipped where the CPU lacks it.
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

#include "desplat/io/colmap.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/init.hpp"

namespace {

using namespace desplat;

struct Scene {
  GaussianSet gaussians;
  Camera camera;
};

Scene frustum_scene(int n) {
  Scene s;
  s.camera.width = 512;
  s.camera.height = 384;
  s.camera.fx = s.camera.fy = 400;
  s.camera.cx = 256;
  s.camera.cy = 192;
  GaussianSet& g = s.gaussians;
  g.sh_degree = 3;
  g.resize(n);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  for (int i = 0; i < n; ++i) {
    const float z = 2 + 8 * u(rng);
    g.means[3 * i] = (u(rng) - 0.5f) * z * 512 / 400;
    g.means[3 * i + 1] = (u(rng) - 0.5f) * z * 384 / 400;
    g.means[3 * i + 2] = z;
    for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(0.005f + 0.03f * u(rng));
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = u(rng) - 0.5f;
    g.opacity_logits[i] = 4 * u(rng) - 2;
  }
  for (float& c : g.colors) c = (u(rng) - 0.5f) * 0.3f;
  return s;
}

// Fox points in the normalized frame of docs/METHOD.md §1, seen from the first image.
Scene fox_scene() {
  const std::filesystem::path dir = DESPLAT_FOX_DIR "/sparse/0";
  const colmap::Model model = colmap::read_model(dir);
  std::vector<std::array<double, 3>> centers;
  for (const auto& [image_id, im] : model.images) {
    (void)image_id;
    Eigen::Quaterniond q(im.qvec_wxyz[0], im.qvec_wxyz[1], im.qvec_wxyz[2], im.qvec_wxyz[3]);
    const Eigen::Vector3d c =
        -(q.normalized().toRotationMatrix().transpose() * Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]));
    centers.push_back({c[0], c[1], c[2]});
  }
  std::array<double, 3> mean{0, 0, 0};
  for (const auto& c : centers)
    for (int k = 0; k < 3; ++k) mean[k] += c[k] / centers.size();
  double extent = 0;
  for (const auto& c : centers)
    for (int k = 0; k < 3; ++k) extent = std::max(extent, std::abs(c[k] - mean[k]));
  const double scale = 1.0 / extent;

  std::vector<std::array<float, 3>> xyz;
  std::vector<std::array<uint8_t, 3>> rgb;
  for (const auto& [point_id, p] : model.points) {
    (void)point_id;
    xyz.push_back({float((p.xyz[0] - mean[0]) * scale), float((p.xyz[1] - mean[1]) * scale),
                   float((p.xyz[2] - mean[2]) * scale)});
    rgb.push_back(p.rgb);
  }
  Scene s;
  s.gaussians = init_gaussians_from_points(xyz, rgb, 3, 1);
  const colmap::Image& im = model.images.begin()->second;
  const colmap::Camera& cam = model.cameras.at(im.camera_id);
  Eigen::Quaterniond q(im.qvec_wxyz[0], im.qvec_wxyz[1], im.qvec_wxyz[2], im.qvec_wxyz[3]);
  const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
  // Normalized frame: p_cam = R (x/scale + mean) + t = (R/scale) x + (R mean + t); keep
  // R orthonormal by scaling the camera-space units instead (depths scale by `scale`).
  const Eigen::Vector3d t =
      (R * Eigen::Vector3d(mean[0], mean[1], mean[2]) + Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2])) * scale;
  s.camera.width = static_cast<int>(cam.width);
  s.camera.height = static_cast<int>(cam.height);
  s.camera.fx = float(cam.params[0]);  // OPENCV: fx fy cx cy k1 k2 p1 p2 (distortion ignored here)
  s.camera.fy = float(cam.params[1]);
  s.camera.cx = float(cam.params[2]);
  s.camera.cy = float(cam.params[3]);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) s.camera.R_cw[3 * r + c] = float(R(r, c));
    s.camera.t_cw[r] = float(t[r]);
  }
  return s;
}

// A trained model (a desplat_train point_cloud.ply of the fox, in the same normalized
// frame) from the environment variable DESPLAT_BENCH_PLY, seen from the fox's first camera:
// the pixel workload of a late training step. Empty when the variable is not set.
Scene trained_fox_scene() {
  const char* ply = std::getenv("DESPLAT_BENCH_PLY");
  Scene s = fox_scene();
  if (!ply) return Scene{};
  s.gaussians = read_gaussian_ply(ply);
  return s;
}

// `s` seen by the same camera at 1/factor of its size (intrinsics scaled with the image).
Scene shrunk(Scene s, int factor) {
  Camera& c = s.camera;
  c.width /= factor;
  c.height /= factor;
  c.fx /= float(factor), c.fy /= float(factor), c.cx /= float(factor), c.cy /= float(factor);
  return s;
}

const Scene& scene_for(int64_t id) {
  static const Scene s100k = frustum_scene(100000);
  static const Scene s500k = frustum_scene(500000);
  if (id == 100000) return s100k;
  if (id == 500000) return s500k;
  if (id == 1) {
    static const Scene trained = trained_fox_scene();
    return trained;
  }
  if (id == 2) {
    static const Scene trained_half = shrunk(trained_fox_scene(), 2);
    return trained_half;
  }
  if (id == 4) {
    static const Scene trained_small = shrunk(trained_fox_scene(), 4);
    return trained_small;
  }
  static const Scene fox = fox_scene();
  return fox;
}

void run(benchmark::State& state, bool backward) {
  const Scene& scene = scene_for(state.range(0));
  if (scene.gaussians.size() == 0) {
    state.SkipWithError("set DESPLAT_BENCH_PLY to a trained fox point_cloud.ply for scenes 1, 2 and 4");
    return;
  }
  RasterSettings settings;
  settings.num_threads = static_cast<int>(state.range(1));
  settings.isa = static_cast<KernelIsa>(state.range(2));
  if (!cpu_supports(settings.isa)) {
    state.SkipWithError((std::string(kernel_isa_name(settings.isa)) + " is not supported by this CPU").c_str());
    return;
  }
  RasterOutput out;
  RasterGradients grads;
  const size_t pixels = size_t(scene.camera.width) * scene.camera.height;
  const std::vector<float> dC(3 * pixels, 1e-3f), dA(pixels, 1e-3f);
  int64_t pairs = 0;
  for (auto _ : state) {
    rasterize_forward(scene.gaussians.view(), scene.camera, settings, out);
    if (backward) rasterize_backward(scene.gaussians.view(), scene.camera, settings, out, dC, dA, {}, grads);
    pairs += out.evaluated_pairs;
    benchmark::DoNotOptimize(out.color.data());
  }
  state.counters["gaussians"] = double(scene.gaussians.size());
  state.counters["pairs"] = benchmark::Counter(double(out.evaluated_pairs));
  // (tile, Gaussian) entries: each costs a fixed setup in both tile passes.
  state.counters["entries"] = benchmark::Counter(double(out.tile_entries.size()));
  // Seconds per evaluated pair (printed with an SI prefix, e.g. "6.1n" = 6.1 ns).
  state.counters["time_per_pair"] =
      benchmark::Counter(double(pairs), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_Forward(benchmark::State& state) { run(state, false); }
void BM_ForwardBackward(benchmark::State& state) { run(state, true); }

// range(0): 100000 / 500000 random Gaussians, 0 = fox at initialization, 1 = a trained
// fox (DESPLAT_BENCH_PLY), 2 and 4 = the trained fox at ½ and ¼ size (½: the full-resolution
// steps of the `--downscale 2` fox run); range(1): threads; range(2): the KernelIsa path.
void args(benchmark::internal::Benchmark* b) {
  for (int64_t scene : {100000, 500000, 0, 1, 2, 4})
    for (int64_t threads : {1, 2})
      for (KernelIsa isa : {KernelIsa::Portable, KernelIsa::Avx2, KernelIsa::Avx512})
        b->Args({scene, threads, static_cast<int64_t>(isa)});
  b->ArgNames({"scene", "threads", "isa"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

// The machine's float FMA throughput, to read the kernels' ns per pair against: 16
// independent accumulators of kLanes floats, each updated by a·x + b (2 flops) per
// iteration, in a loop the compiler turns into FMA instructions of the widest vectors
// -march=native allows. Reports flops per second per benchmark thread count.
void BM_FmaPeak(benchmark::State& state) {
  constexpr int kLanes = 16, kChains = 16;
  const int threads = static_cast<int>(state.range(0));
  const int64_t iterations = 1 << 20;
  float sink = 0;
  for (auto _ : state) {
#pragma omp parallel num_threads(threads) reduction(+ : sink)
    {
      alignas(64) float acc[kChains][kLanes];
      for (int c = 0; c < kChains; ++c)
        for (int l = 0; l < kLanes; ++l) acc[c][l] = float(c + l) * 1e-3f;
      const float a = 0.999f, b = 1e-4f;
      for (int64_t it = 0; it < iterations; ++it)
        for (int c = 0; c < kChains; ++c)
#pragma omp simd
          for (int l = 0; l < kLanes; ++l) acc[c][l] = acc[c][l] * a + b;
      for (int c = 0; c < kChains; ++c)
        for (int l = 0; l < kLanes; ++l) sink += acc[c][l];
    }
  }
  benchmark::DoNotOptimize(sink);
  state.counters["flops"] = benchmark::Counter(double(state.iterations()) * threads * iterations * kChains * kLanes * 2,
                                               benchmark::Counter::kIsRate);
}
BENCHMARK(BM_FmaPeak)->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK(BM_Forward)->Apply(args);
BENCHMARK(BM_ForwardBackward)->Apply(args);

}  // namespace

BENCHMARK_MAIN();
