// desplat_bench: trains a grid of settings on one or more scenes and plots test accuracy
// (PSNR, SSIM, mask IoU) against training wall time, and against clutter ratio. The grid
// format and the outputs are described in include/desplat/jobs/bench_run.hpp.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <optional>

#include "desplat/jobs/bench_run.hpp"
#include "desplat/jobs/report.hpp"
#include "stop_signal.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Benchmark what accuracy costs in time: train every run of --grid on every scene it lists, score\n"
      "the test views every eval_every steps, write --out/bench.csv and PNG plots. Ctrl-C stops after\n"
      "the current step; what was measured stays in bench.csv and --resume skips finished runs."};
  std::filesystem::path grid_file, out_dir;
  bool resume = false, plot_only = false;
  app.add_option("--grid", grid_file, "benchmark grid (JSON)")->required()->check(CLI::ExistingFile);
  app.add_option("--out", out_dir, "output folder for bench.csv and the plots")->required();
  app.add_flag("--resume", resume, "keep finished runs of an existing --out/bench.csv");
  std::optional<int> threads;
  app.add_option("--threads", threads, "OpenMP threads per run, overriding the grid's (0 = all cores)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--plot-only", plot_only, "only redraw the plots from --out/bench.csv");
  CLI11_PARSE(app, argc, argv);
  const std::atomic<bool>& stop = desplat_apps::stop_on_signals();
  try {
    desplat::BenchGrid grid = desplat::read_bench_grid(grid_file);
    if (threads) grid.threads = *threads;
    std::vector<desplat::BenchPoint> points;
    if (plot_only) {
      points = desplat::read_bench_csv(out_dir / "bench.csv");
    } else {
      points = desplat::run_bench(grid, out_dir, resume, stop, [](const desplat::BenchPoint& p) {
        std::printf("%s / %s: step %lld, %.1f s, PSNR %.2f dB, SSIM %.4f", p.scene.c_str(), p.run.c_str(),
                    (long long)p.step, p.train_seconds, p.psnr, p.ssim);
        if (p.mask_iou >= 0 && p.desplat) std::printf(", mask IoU %.3f", p.mask_iou);
        std::printf(", %zu + %zu Gaussians\n", p.static_gaussians, p.distractor_gaussians);
        std::fflush(stdout);
      });
    }
    for (const auto& file : desplat::write_bench_plots(out_dir, points)) std::printf("wrote %s\n", file.c_str());
    const desplat::ReportResult page = desplat::write_bench_report(out_dir, points);
    std::printf("wrote %s (open it in a browser)%s%s\n", page.path.c_str(), page.note.empty() ? "" : ": ",
                page.note.c_str());
    std::printf("wrote %s\n", (out_dir / "bench.csv").c_str());
    if (stop.load()) {
      std::printf("interrupted; continue with --resume\n");
      return 130;
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "desplat_bench: error: %s\n", e.what());
    return 1;
  }
}
