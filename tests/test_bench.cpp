// desplat_bench's parts: the line plot against its own frame, the CSV round trip, grid
// validation, and a tiny end-to-end grid on a generated scene with masks (resume included).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "desplat/eval/plot.hpp"
#include "desplat/io/atomic_file.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/jobs/bench_run.hpp"
#include "desplat/jobs/clutter_summary.hpp"
#include "desplat/jobs/report.hpp"
#include "desplat/synth/synth.hpp"
#include "desplat/train/presets.hpp"
#include "support/expect.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;

// Every folder temp_dir made is removed when the test program ends, whatever the test did.
struct TempDirs {
  std::vector<fs::path> made;
  ~TempDirs() {
    std::error_code ignored;
    for (const fs::path& p : made) fs::remove_all(p, ignored);
  }
};

fs::path temp_dir(const std::string& name) {
  static TempDirs dirs;
  const fs::path p = fs::temp_directory_path() / ("desplat_test_bench_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(p);
  fs::create_directories(p);
  dirs.made.push_back(p);
  return p;
}

// gnuplot's SVG records the axis ranges it chose for its mouse script.
double svg_axis(const std::string& svg, const std::string& name) {
  const std::string key = "gnuplot_svg.plot_axis_" + name + " = ";
  const size_t at = svg.find(key);
  if (at == std::string::npos) return NAN;
  return std::stod(svg.substr(at + key.size()));
}

TEST(Plot, SvgHasTheTitlesLegendAndAxesThatHoldTheData) {
  if (!plotting_available()) FAIL() << "gnuplot is not installed: run scripts/install_deps.sh";
  const fs::path dir = temp_dir("plot_svg");
  const std::vector<PlotSeries> series = {{"flat", {0, 5, 10}, {2, 2, 2}}, {"rising's", {0, 10}, {1, 3}}};
  const std::string svg = draw_plot(line_plot("PSNR vs time", "seconds", "dB"), series, PlotFormat::Svg, dir);
  for (const char* text : {"PSNR vs time", "seconds", ">dB<", ">flat<", ">rising's<", "<svg"})
    EXPECT_NE(svg.find(text), std::string::npos) << text;
  // The axes hold the data ([0, 10] × [1, 3]) and no more than a tick step beyond it.
  EXPECT_LE(svg_axis(svg, "xmin"), 0);
  EXPECT_GE(svg_axis(svg, "xmax"), 10);
  EXPECT_LE(svg_axis(svg, "ymin"), 1);
  EXPECT_GE(svg_axis(svg, "ymax"), 3);
  EXPECT_GT(svg_axis(svg, "ymin"), 0);
  EXPECT_LT(svg_axis(svg, "ymax"), 4);
  EXPECT_TRUE(fs::is_empty(dir));  // gnuplot's script and output are removed
}

TEST(Plot, PngIsAnImageOfTheAskedSizeWithTheSeriesColours) {
  if (!plotting_available()) FAIL() << "gnuplot is not installed: run scripts/install_deps.sh";
  const fs::path dir = temp_dir("plot_png");
  const std::vector<PlotSeries> series = {{"a", {0, 1, 2}, {0, 1, 4}}, {"b", {0, 2}, {4, 0}}};
  PlotSpec spec = line_plot("t", "x", "y");
  spec.width = 640, spec.height = 400;
  const std::string png = draw_plot(spec, series, PlotFormat::Png, dir);
  write_file_atomically(dir / "p.png", png);
  const FloatImage im = read_image_rgb(dir / "p.png");
  ASSERT_EQ(im.width, 640);
  ASSERT_EQ(im.height, 400);
  // gnuplot's first two line colours, #9400d3 and #009e73, are drawn.
  int first = 0, second = 0;
  for (size_t p = 0; p < im.pixels.size(); p += 3) {
    const float r = im.pixels[p], g = im.pixels[p + 1], b = im.pixels[p + 2];
    first += std::abs(r - 0x94 / 255.f) < 0.05f && g < 0.05f && std::abs(b - 0xd3 / 255.f) < 0.05f;
    second += r < 0.05f && std::abs(g - 0x9e / 255.f) < 0.05f && std::abs(b - 0x73 / 255.f) < 0.05f;
  }
  EXPECT_GT(first, 100);
  EXPECT_GT(second, 100);
}

TEST(Plot, BadSeriesAreErrors) {
  const fs::path dir = temp_dir("plot_bad");
  EXPECT_THROW(draw_plot(line_plot("t", "x", "y"), {{"a", {1, 2}, {1}}}, PlotFormat::Svg, dir), std::invalid_argument);
  EXPECT_THROW(draw_plot(line_plot("t", "x", "y"), {{"a", {NAN}, {1}}}, PlotFormat::Svg, dir), std::invalid_argument);
  PlotSpec bars = line_plot("t", "", "ms");
  bars.bars = true;  // without labels
  EXPECT_THROW(draw_plot(bars, {{"a", {0, 1}, {1, 2}}}, PlotFormat::Svg, dir), std::invalid_argument);
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
  // A static-only run on the clean scene: the summary and its recovered-fraction plot.
  EXPECT_NE(std::find(plots.begin(), plots.end(), dir / "clutter_summary.csv"), plots.end());
  EXPECT_NE(std::find(plots.begin(), plots.end(), dir / "recovered_vs_clutter.png"), plots.end());
  // No masks anywhere: no IoU plots.
  for (const fs::path& p : plots) EXPECT_EQ(p.string().find("iou_"), std::string::npos) << p;
  fs::remove_all(dir);
}

// Hand-computed: clean (static-only at 0 %) 33 dB; at 50 % static-only 30, DeSplat 32, so
// DeSplat wins back (32 − 30) / (33 − 30) = 2/3 of what clutter cost; at 100 % 27 and 31.5:
// 4.5 / 6 = 0.75. At 0 % clutter cost nothing: no fraction. Earlier steps and a scene
// without a ratio do not count.
TEST(ClutterSummary, RecoveredFractionAgainstTheCleanBaseline) {
  std::vector<BenchPoint> points;
  auto add = [&](const std::string& scene, double ratio, bool desplat, int64_t step, double psnr, double iou) {
    BenchPoint p;
    p.scene = scene, p.clutter_ratio = ratio, p.desplat = desplat, p.run = desplat ? "DeSplat" : "static-only";
    p.step = step, p.psnr = psnr, p.mask_iou = iou, p.train_seconds = double(step) / 10;
    points.push_back(p);
  };
  add("c100", 1.0, true, 7000, 31.5, 0.7);
  add("c000", 0.0, false, 3500, 20.0, -1);  // an earlier point of the clean baseline
  add("c000", 0.0, false, 7000, 33.0, -1);
  add("c000", 0.0, true, 7000, 32.8, -1);
  add("c050", 0.5, true, 7000, 32.0, 0.8);
  add("c050", 0.5, false, 7000, 30.0, 0);
  add("c100", 1.0, false, 7000, 27.0, 0);
  add("other", -1, true, 7000, 10.0, 0.1);  // no clutter ratio
  add("other", -1, false, 7000, 40.0, 0);
  const std::vector<ClutterSummaryRow> rows = clutter_summary(points);
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].clutter_ratio, 0.0);
  EXPECT_TRUE(std::isnan(rows[0].recovered));
  EXPECT_EQ(rows[0].psnr, 32.8);
  EXPECT_EQ(rows[1].clutter_ratio, 0.5);
  EXPECT_NEAR(rows[1].recovered, 2.0 / 3.0, 1e-12);
  EXPECT_EQ(rows[1].mask_iou, 0.8);
  EXPECT_EQ(rows[1].clean_psnr, 33.0);
  EXPECT_NEAR(rows[2].recovered, 0.75, 1e-12);
  EXPECT_EQ(rows[2].static_only_psnr, 27.0);
  EXPECT_EQ(rows[2].train_seconds, 700.0);

  const fs::path dir = temp_dir("summary");
  write_clutter_summary_csv(dir / "s.csv", rows);
  std::ifstream f(dir / "s.csv");
  std::string header, zero, half;
  std::getline(f, header), std::getline(f, zero), std::getline(f, half);
  EXPECT_EQ(zero, "0,DeSplat,32.8,33,33,,-1,700,700");
  EXPECT_EQ(half, "0.5,DeSplat,32,30,33,0.666667,0.8,700,700");
  fs::remove_all(dir);

  // Without a static-only run on a clutter-free scene there is nothing to measure against.
  points.erase(points.begin() + 1, points.begin() + 3);
  EXPECT_TRUE(clutter_summary(points).empty());
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
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x", "preset": "quick"}]})")
                .find("run 'x': unknown preset 'quick'"),
            std::string::npos);
  // Numbers beyond the setting's type are refused before any conversion to int (undefined there).
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x", "downscale": 8.9e95}]})")
                .find("downscale must be a whole number in"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x"}], "threads": 2.5})").find("threads must be a whole"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"scenes": ["a"], "runs": [{"name": "x"}], "steps": -1e300})").find("steps must be a whole"),
            std::string::npos);
  fs::remove_all(dir);
}

// A run's preset is its starting configuration, as in desplat_train --preset; the grid's
// steps apply only to runs without one, and a run's config overrides both.
TEST(BenchGrid, RunsStartFromTheirPresetAndKeepItsLength) {
  const fs::path dir = temp_dir("grid_presets");
  std::ofstream(dir / "g.json") << R"({"scenes": ["a"], "steps": 50, "threads": 1, "runs": [
    {"name": "plain"}, {"name": "fast", "preset": "fast"}, {"name": "paper", "preset": "paper"},
    {"name": "fast 10 steps", "preset": "fast", "config": {"iterations": 10, "densify": {"warmup": 7}}}]})";
  const BenchGrid g = read_bench_grid(dir / "g.json");
  ASSERT_EQ(g.runs.size(), 4u);
  const TrainConfig plain = bench_run_config(g, g.runs[0]), fast = bench_run_config(g, g.runs[1]),
                    paper = bench_run_config(g, g.runs[2]), short_fast = bench_run_config(g, g.runs[3]);
  EXPECT_EQ(plain.iterations, 50);
  EXPECT_EQ(fast.iterations, preset_config("fast").iterations);
  EXPECT_EQ(fast.resolution_schedule, preset_config("fast").resolution_schedule);
  EXPECT_EQ(paper.iterations, preset_config("paper").iterations);
  EXPECT_TRUE(paper.densify.stats.visible_count_from_one);
  EXPECT_FALSE(plain.densify.stats.visible_count_from_one);
  EXPECT_EQ(short_fast.iterations, 10);
  EXPECT_EQ(short_fast.densify.warmup, 7);
  EXPECT_EQ(short_fast.resolution_schedule, preset_config("fast").resolution_schedule);
  for (const TrainConfig* c : {&plain, &fast, &paper, &short_fast}) EXPECT_EQ(c->threads, 1);
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
  EXPECT_EQ(grids, 7);  // bench_grid, bench_grid_quick, bench_grid_7k_half, clutter_grid, clutter_tracks_grid,
                        // presets_fox_grid, presets_synth_grid
}

TEST(Bench, TinyGridWritesCurvesPlotsAndResumes) {
  const fs::path dir = temp_dir("e2e");
  synth::GenerateOptions g;
  g.out = dir / "tiny";
  synth::generate_scene(synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_distractors.json"),
                        g);
  std::ofstream(dir / "grid.json") << R"({
    "scenes": ["tiny"], "steps": 20, "eval_every": 10, "threads": 2,
    "runs": [{"name": "DeSplat", "config": {"num_downscales": 0}},
             {"name": "static-only", "config": {"num_downscales": 0, "distractors": {"enabled": false}}}]})";
  const BenchGrid grid = read_bench_grid(dir / "grid.json");
  std::atomic<bool> stop{false};
  int reported = 0;
  const std::vector<BenchPoint> points =
      run_bench(grid, dir / "out", false, stop, [&](const BenchPoint&) { ++reported; });
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
  // The page: PSNR and IoU against time for the one scene, and both runs' final points.
  const ReportResult page = write_bench_report(dir / "out", points);
  EXPECT_EQ(page.plots, 2) << page.note;
  const std::string html = testing::slurp(page.path);
  size_t frames = 0;
  for (size_t at = html.find("<iframe class=\"plot\""); at != std::string::npos;
       at = html.find("<iframe class=\"plot\"", at + 1))
    ++frames;
  EXPECT_EQ(frames, 2u);
  for (const BenchPoint& p : points) EXPECT_NE(html.find("<td>" + p.run + "</td>"), std::string::npos) << p.run;
  EXPECT_FALSE(fs::exists(dir / "out" / ".report_tmp"));
  // Resuming with everything finished trains nothing and keeps every point.
  reported = 0;
  const std::vector<BenchPoint> again =
      run_bench(grid, dir / "out", true, stop, [&](const BenchPoint&) { ++reported; });
  EXPECT_EQ(reported, 0);
  EXPECT_EQ(again.size(), 4u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace desplat
