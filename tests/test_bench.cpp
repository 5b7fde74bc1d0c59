// desplat_bench's parts: the line plot against its own frame, the CSV round trip, grid
// validation, and a tiny end-to-end grid on a generated scene with masks (resume included).
#include <gtest/gtest.h>

#include <fstream>

#include "desplat/jobs/bench_run.hpp"
#include "desplat/eval/line_plot.hpp"
#include "desplat/synth/synth.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

fs::path temp_dir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("desplat_test_bench_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

std::array<float, 3> pixel(const FloatImage& im, double x, double y) {
  const size_t i = (size_t(std::lround(y)) * im.width + size_t(std::lround(x))) * 3;
  return {im.pixels[i], im.pixels[i + 1], im.pixels[i + 2]};
}

bool near(const std::array<float, 3>& a, const std::array<float, 3>& b) {
  return std::abs(a[0] - b[0]) < 0.02f && std::abs(a[1] - b[1]) < 0.02f && std::abs(a[2] - b[2]) < 0.02f;
}

TEST(LinePlot, CurvesLandWhereTheirDataSays) {
  const std::vector<PlotSeries> series = {{"flat", {0, 5, 10}, {2, 2, 2}}, {"rising", {0, 10}, {1, 3}}};
  const PlotSpec spec{"t", "x", "y"};
  const PlotFrame f = plot_frame(spec, series);
  // Data range [0, 10] × [1, 3] plus 5 % margins.
  EXPECT_DOUBLE_EQ(f.x_min, -0.5);
  EXPECT_DOUBLE_EQ(f.x_max, 10.5);
  EXPECT_DOUBLE_EQ(f.y_min, 0.9);
  EXPECT_DOUBLE_EQ(f.y_max, 3.1);
  const FloatImage im = draw_line_plot(spec, series);
  ASSERT_EQ(im.width, spec.width);
  // On the flat line, between its markers, and on the rising line at x = 2.5 (y = 1.5).
  EXPECT_TRUE(near(pixel(im, f.pixel_x(2.5), f.pixel_y(2)), plot_color(0)));
  EXPECT_TRUE(near(pixel(im, f.pixel_x(2.5), f.pixel_y(1.5)), plot_color(1)));
  // Well off both lines the plot is background (white or a light grid line).
  const auto off = pixel(im, f.pixel_x(7.3), f.pixel_y(1.2));
  EXPECT_GT(off[0], 0.85f);
  EXPECT_GT(off[2], 0.85f);
}

TEST(LinePlot, TicksAreRoundNumbersInsideTheAxis) {
  const std::vector<double> seconds = nice_ticks(-14.75, 661.6);  // the time axis of a bench plot
  EXPECT_EQ(seconds, (std::vector<double>{0, 100, 200, 300, 400, 500, 600}));
  const std::vector<double> psnr = nice_ticks(20.85, 27.8);
  EXPECT_EQ(psnr, (std::vector<double>{21, 22, 23, 24, 25, 26, 27}));
  const std::vector<double> iou = nice_ticks(-0.041, 0.867);
  ASSERT_EQ(iou.size(), 5u);  // 0, 0.2, …, 0.8
  for (size_t i = 0; i < iou.size(); ++i) EXPECT_NEAR(iou[i], 0.2 * double(i), 1e-12);
  const std::vector<double> narrow = nice_ticks(0.9, 3.1);  // step 0.5: 1, 1.5, …, 3 (0.2 would give 11)
  ASSERT_EQ(narrow.size(), 5u);
  EXPECT_DOUBLE_EQ(narrow.front(), 1.0);
  EXPECT_DOUBLE_EQ(narrow.back(), 3.0);
  EXPECT_TRUE(nice_ticks(1, 1).empty());
  EXPECT_TRUE(nice_ticks(0, NAN).empty());
}

TEST(LinePlot, BadSeriesAreErrors) {
  EXPECT_THROW(draw_line_plot({}, {{"a", {1, 2}, {1}}}), std::invalid_argument);
  EXPECT_THROW(draw_line_plot({}, {{"a", {NAN}, {1}}}), std::invalid_argument);
  // One point still gets a frame around it.
  const PlotFrame f = plot_frame({}, {{"a", {3}, {4}}});
  EXPECT_LT(f.x_min, 3);
  EXPECT_GT(f.y_max, 4);
}

TEST(BenchCsv, RoundTripsAndNamesTheBadLine) {
  const fs::path dir = temp_dir("csv");
  BenchPoint a;
  a.scene = "s", a.run = "DeSplat", a.clutter_ratio = 0.4, a.step = 500, a.train_seconds = 12.25, a.psnr = 27.5;
  a.ssim = 0.875, a.mask_iou = 0.625, a.static_gaussians = 1234, a.distractor_gaussians = 99;
  BenchPoint b = a;
  b.run = "static-only", b.desplat = false, b.mask_iou = -1;
  write_bench_csv(dir / "bench.csv", {a, b});
  const std::vector<BenchPoint> back = read_bench_csv(dir / "bench.csv");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].run, "DeSplat");
  EXPECT_DOUBLE_EQ(back[0].train_seconds, 12.25);
  EXPECT_DOUBLE_EQ(back[0].mask_iou, 0.625);
  EXPECT_EQ(back[0].distractor_gaussians, 99u);
  EXPECT_FALSE(back[1].desplat);
  std::ofstream(dir / "bench.csv", std::ios::app) << "s,0.4,x,1,oops\n";
  try {
    read_bench_csv(dir / "bench.csv");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("line 4"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

TEST(BenchPlots, ClutterPlotWhenScenesCarryRatios) {
  const fs::path dir = temp_dir("plots");
  std::vector<BenchPoint> points;
  for (const double ratio : {0.0, 0.5, 1.0})
    for (const bool desplat : {true, false}) {
      BenchPoint p;
      p.scene = "clutter_" + std::to_string(int(100 * ratio)), p.clutter_ratio = ratio, p.desplat = desplat;
      p.run = desplat ? "DeSplat" : "static-only", p.step = 100, p.train_seconds = 1, p.psnr = 30 - 3 * ratio;
      points.push_back(p);
    }
  const std::vector<fs::path> plots = write_bench_plots(dir, points);
  EXPECT_NE(std::find(plots.begin(), plots.end(), dir / "psnr_vs_clutter.png"), plots.end());
  // No masks anywhere: no IoU plots.
  for (const fs::path& p : plots) EXPECT_EQ(p.string().find("_iou_"), std::string::npos) << p;
  fs::remove_all(dir);
}

TEST(BenchGrid, InvalidGridsNameTheFileAndTheProblem) {
  const fs::path dir = temp_dir("grid");
  auto error_of = [&](const std::string& text) {
    std::ofstream(dir / "g.json") << text;
    try {
      read_bench_grid(dir / "g.json");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x"}], "stepz": 3})").find("unknown setting 'stepz'"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x"}, {"name": "x"}]})").find("two runs named 'x'"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x", "config": {"lr": {"meens": 1}}}]})").find("run 'x'"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": [], "runs": [{"name": "x"}]})").find("no scenes"), std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x"}], "score_at": "half"})").find("score_at"),
            std::string::npos);
  EXPECT_NE(error_of("{").find((dir / "g.json").string()), std::string::npos);
  fs::remove_all(dir);
}

TEST(BenchGrid, CheckedInGridsAreValid) {
  int grids = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(DESPLAT_SOURCE_DIR) / "data/bench")) {
    if (entry.path().filename().string().find("grid") == std::string::npos) continue;
    const BenchGrid g = read_bench_grid(entry.path());
    EXPECT_FALSE(g.runs.empty()) << entry.path();
    ++grids;
  }
  EXPECT_EQ(grids, 4);  // bench_grid, bench_grid_quick, bench_grid_7k_half, clutter_grid
}

TEST(Bench, TinyGridWritesCurvesPlotsAndResumes) {
  const fs::path dir = temp_dir("e2e");
  synth::GenerateOptions g;
  g.out = dir / "tiny";
  synth::generate_scene(synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_distractors.json"), g);
  std::ofstream(dir / "grid.json") << R"({
    "scenes": ["tiny"], "steps": 20, "eval_every": 10, "threads": 2,
    "runs": [{"name": "DeSplat", "config": {"num_downscales": 0}},
             {"name": "static-only", "config": {"num_downscales": 0, "distractors": {"enabled": false}}}]})";
  const BenchGrid grid = read_bench_grid(dir / "grid.json");
  std::atomic<bool> stop{false};
  int reported = 0;
  const std::vector<BenchPoint> points = run_bench(grid, dir / "out", false, stop, [&](const BenchPoint&) { ++reported; });
  ASSERT_EQ(points.size(), 4u);  // two runs × steps 10 and 20
  EXPECT_EQ(reported, 4);
  for (const BenchPoint& p : points) {
    EXPECT_EQ(p.scene, "tiny");
    EXPECT_DOUBLE_EQ(p.clutter_ratio, 0.5);  // from the generated scene.json
    EXPECT_GT(p.psnr, 5.0);
    EXPECT_GT(p.train_seconds, 0.0);
    EXPECT_GE(p.mask_iou, 0.0);  // the scene has masks
  }
  EXPECT_LT(points[0].train_seconds, points[1].train_seconds);
  EXPECT_GT(points[0].distractor_gaussians, 0u);
  EXPECT_EQ(points[2].distractor_gaussians, 0u);
  EXPECT_EQ(read_bench_csv(dir / "out" / "bench.csv").size(), 4u);
  const std::vector<fs::path> plots = write_bench_plots(dir / "out", points);
  EXPECT_EQ(plots.size(), 3u);  // PSNR, SSIM, IoU against time; one scene, so no clutter plot
  for (const fs::path& p : plots) EXPECT_TRUE(fs::exists(p)) << p;
  // Resuming with everything finished trains nothing and keeps every point.
  reported = 0;
  const std::vector<BenchPoint> again = run_bench(grid, dir / "out", true, stop, [&](const BenchPoint&) { ++reported; });
  EXPECT_EQ(reported, 0);
  EXPECT_EQ(again.size(), 4u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace desplat
