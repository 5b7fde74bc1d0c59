#include "desplat/jobs/bench_run.hpp"
#include "desplat/io/json_text.hpp"
#include "desplat/io/output_folder.hpp"

#include "desplat/core/stopwatch.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <stdexcept>

#include "desplat/eval/mask_metrics.hpp"
#include "desplat/eval/plot.hpp"
#include "desplat/io/atomic_file.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/jobs/clutter_summary.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"

namespace desplat {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kCsvHeader =
    "scene,clutter_ratio,run,desplat,step,train_seconds,psnr,ssim,mask_iou,static_gaussians,distractor_gaussians";

// The clutter ratio desplat_synth recorded in <scene>/scene.json; -1 when there is none.
double scene_clutter_ratio(const fs::path& scene) {
  std::ifstream f(scene / "scene.json");
  if (!f) return -1;
  try {
    const json j = parse_json_bounded(f, (scene / "scene.json").string());
    return j.at("distractors").at("clutter_ratio").get<double>();
  } catch (const json::exception&) {
    return -1;
  }
}

std::string scene_name(const fs::path& scene) {
  const fs::path p = scene.has_filename() ? scene : scene.parent_path();
  return p.filename().string();
}

bool finished(const std::vector<BenchPoint>& points, const std::string& scene, const std::string& run, int64_t steps) {
  return std::any_of(points.begin(), points.end(),
                     [&](const BenchPoint& p) { return p.scene == scene && p.run == run && p.step == steps; });
}

double mean(const std::vector<ViewMetrics>& m, double ViewMetrics::*field) {
  double s = 0;
  for (const ViewMetrics& v : m) s += v.*field;
  return m.empty() ? 0 : s / m.size();
}

}  // namespace

TrainConfig bench_run_config(const BenchGrid& grid, const BenchRun& run) {
  TrainConfig c = config_from_json(run.config, preset_config(run.preset.empty() ? "default" : run.preset));
  // A preset's own length stands (fast is 3,000 steps); otherwise the grid's.
  if (!run.config.contains("iterations") && run.preset.empty()) c.iterations = grid.steps;
  c.threads = grid.threads;
  return c;
}

BenchGrid read_bench_grid(const fs::path& file) {
  std::ifstream f(file);
  if (!f) throw std::invalid_argument("cannot read benchmark grid " + file.string());
  json j;
  try {
    j = parse_json_bounded(f, file.string(), /*ignore_comments=*/true);
  } catch (const json::exception& e) {
    throw std::invalid_argument(file.string() + " is not valid JSON: " + e.what());
  }
  auto fail = [&](const std::string& what) { throw std::invalid_argument(file.string() + ": " + what); };
  if (!j.is_object()) fail("expected a JSON object");
  // A whole number in [lo, hi] (an integral float such as 2.0 too): a JSON number beyond the
  // target type's range would otherwise be converted with undefined behaviour.
  auto whole = [&](const json& v, const std::string& name, int64_t lo, int64_t hi) -> int64_t {
    if (!v.is_number()) return v.get<int64_t>();  // throws: the wrong type's message below
    const double d = v.get<double>();
    if (!(d >= double(lo) && d <= double(hi)) || d != std::floor(d))
      fail(name + " must be a whole number in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], not " +
           v.dump());
    return v.is_number_integer() ? v.get<int64_t>() : int64_t(d);
  };
  constexpr int64_t kIntMax = std::numeric_limits<int>::max(), kStepsMax = int64_t(1) << 60;
  BenchGrid g;
  std::string current;  // the setting being read, for a wrong type's message
  try {
    for (const auto& [key, value] : j.items()) {
      current = key;
      if (key == "scenes") {
        if (!value.is_array()) fail("\"scenes\" must be a list of scene folders, e.g. [\"out/bench\"]");
        for (const json& s : value) g.scenes.push_back(fs::absolute(file).parent_path() / s.get<std::string>());
      } else if (key == "steps") {
        g.steps = whole(value, "steps", -kStepsMax, kStepsMax);
      } else if (key == "eval_every") {
        g.eval_every = int(whole(value, "eval_every", -kIntMax, kIntMax));
      } else if (key == "threads") {
        g.threads = int(whole(value, "threads", -kIntMax, kIntMax));
      } else if (key == "score_at") {
        const std::string where = value.get<std::string>();
        if (where != "full" && where != "training") fail("score_at must be \"full\" or \"training\"");
        g.score_at_full_resolution = where == "full";
      } else if (key == "runs") {
        if (!value.is_array()) fail("\"runs\" must be a list of runs, e.g. [{\"name\": \"default\"}]");
        for (const json& r : value) {
          if (!r.is_object())
            fail("each entry of \"runs\" must be an object such as {\"name\": \"default\"}, not " + r.dump());
          BenchRun run;
          for (const auto& [rk, rv] : r.items()) {
            if (rk == "name")
              run.name = rv.get<std::string>();
            else if (rk == "config")
              run.config = rv;
            else if (rk == "downscale")
              run.downscale = int(whole(rv, "downscale", -kIntMax, kIntMax));
            else if (rk == "preset")
              run.preset = rv.get<std::string>();
            else
              fail("unknown run setting '" + rk + "'");
          }
          g.runs.push_back(run);
        }
      } else {
        fail("unknown setting '" + key + "'");
      }
    }
  } catch (const json::exception& e) {
    fail("\"" + current + "\" has the wrong type (" + json_error_text(e) + ")");
  }
  if (g.scenes.empty()) fail("no scenes");
  if (g.runs.empty()) fail("no runs");
  if (g.steps < 1 || g.eval_every < 1 || g.threads < 0) fail("steps and eval_every must be ≥ 1, threads ≥ 0");
  std::set<std::string> names;
  for (const BenchRun& r : g.runs) {
    if (r.name.empty()) fail("a run without a name");
    if (r.name.find_first_of(",\"\n") != std::string::npos)
      fail("run name '" + r.name + "' contains , \" or a newline");
    if (!names.insert(r.name).second) fail("two runs named '" + r.name + "'");
    if (r.downscale < 1) fail("run '" + r.name + "': downscale must be ≥ 1");
    try {
      bench_run_config(g, r);
    } catch (const std::invalid_argument& e) {
      fail("run '" + r.name + "': " + e.what());
    }
  }
  return g;
}

void write_bench_csv(const fs::path& path, const std::vector<BenchPoint>& points) {
  std::ostringstream s;
  s.precision(10);
  s << kCsvHeader << "\n";
  for (const BenchPoint& p : points)
    s << p.scene << "," << p.clutter_ratio << "," << p.run << "," << int(p.desplat) << "," << p.step << ","
      << p.train_seconds << "," << p.psnr << "," << p.ssim << "," << p.mask_iou << "," << p.static_gaussians << ","
      << p.distractor_gaussians << "\n";
  write_file_atomically(path, s.str());
}

std::vector<BenchPoint> read_bench_csv(const fs::path& path) {
  std::ifstream f(path);
  if (!f) throw std::invalid_argument("cannot read " + path.string());
  std::string line;
  if (!std::getline(f, line) || line != kCsvHeader)
    throw std::invalid_argument(path.string() + ": not a desplat_bench CSV (unexpected header)");
  std::vector<BenchPoint> points;
  for (int number = 2; std::getline(f, line); ++number) {
    std::vector<std::string> cells;
    std::stringstream ls(line);
    for (std::string cell; std::getline(ls, cell, ',');) cells.push_back(cell);
    try {
      if (cells.size() != 11) throw std::invalid_argument("expected 11 cells");
      BenchPoint p;
      p.scene = cells[0], p.clutter_ratio = std::stod(cells[1]), p.run = cells[2];
      p.desplat = std::stoi(cells[3]) != 0, p.step = std::stoll(cells[4]), p.train_seconds = std::stod(cells[5]);
      p.psnr = std::stod(cells[6]), p.ssim = std::stod(cells[7]), p.mask_iou = std::stod(cells[8]);
      p.static_gaussians = std::stoull(cells[9]), p.distractor_gaussians = std::stoull(cells[10]);
      points.push_back(p);
    } catch (const std::exception& e) {
      throw std::invalid_argument(path.string() + " line " + std::to_string(number) + ": malformed (" + e.what() + ")");
    }
  }
  return points;
}

std::vector<BenchPoint> run_bench(const BenchGrid& grid, const fs::path& out_dir, bool resume,
                                  const std::atomic<bool>& stop_requested,
                                  const std::function<void(const BenchPoint&)>& report) {
  for (const fs::path& scene : grid.scenes) check_output_folder("--out", out_dir, {{"the grid's scene", scene}});
  fs::create_directories(out_dir);
  const fs::path csv = out_dir / "bench.csv";
  std::vector<BenchPoint> points;
  if (resume && fs::exists(csv)) points = read_bench_csv(csv);
  for (const fs::path& scene_dir : grid.scenes) {
    const std::string name = scene_name(scene_dir);
    const double clutter = scene_clutter_ratio(scene_dir);
    std::unique_ptr<TrainingData> full;  // full-resolution test views, loaded when first needed
    for (const BenchRun& run : grid.runs) {
      const TrainConfig config = bench_run_config(grid, run);
      if (finished(points, name, run.name, config.iterations)) continue;
      // An unfinished run starts over: drop its partial points.
      std::erase_if(points, [&](const BenchPoint& p) { return p.scene == name && p.run == run.name; });
      SceneOptions options;
      options.downscale = run.downscale;
      const Scene scene = load_colmap_scene(scene_dir, options);
      const TrainingData data = load_training_data(scene);
      if (!full && grid.score_at_full_resolution) {
        if (run.downscale == 1) {
          full = std::make_unique<TrainingData>(data);
        } else {
          full = std::make_unique<TrainingData>(load_training_data(load_colmap_scene(scene_dir, SceneOptions{})));
        }
      }
      const std::vector<TrainView>& test_views = grid.score_at_full_resolution ? full->test : data.test;
      if (test_views.empty()) throw std::invalid_argument(scene_dir.string() + " has no test views to score");
      const bool has_masks =
          std::any_of(scene.views.begin(), scene.views.end(), [](const SceneView& v) { return !v.mask_path.empty(); });
      Trainer trainer(data, config);
      double seconds = 0;
      while (trainer.current_step() < config.iterations) {
        if (stop_requested.load()) return points;
        const Stopwatch watch;
        const int64_t before = trainer.current_step();
        trainer.step();
        seconds += watch.seconds();
        const int64_t step = trainer.current_step();
        // A batch of views advances the count by more than one: score where it passes a multiple.
        if (step / grid.eval_every == before / grid.eval_every && step != config.iterations) continue;
        const std::vector<ViewMetrics> m = trainer.evaluate(test_views);
        BenchPoint p;
        p.scene = name, p.run = run.name, p.clutter_ratio = clutter, p.desplat = config.distractors.enabled;
        p.step = step, p.train_seconds = seconds;
        p.psnr = mean(m, &ViewMetrics::psnr), p.ssim = mean(m, &ViewMetrics::ssim);
        if (has_masks) {
          const MaskMetrics masks = evaluate_distractor_masks(trainer, scene);
          if (masks.occluded_views > 0) p.mask_iou = masks.mean_iou;  // no occluded view: no IoU
        }
        p.static_gaussians = trainer.gaussians().size(), p.distractor_gaussians = trainer.distractor_count();
        points.push_back(p);
        write_bench_csv(csv, points);
        if (report) report(p);
      }
    }
  }
  return points;
}

namespace {

// One PNG through eval/plot.hpp (gnuplot), written atomically; gnuplot's scratch files go in
// a hidden folder next to it.
void write_plot(const fs::path& file, const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  const fs::path scratch = file.parent_path() / ".plot_tmp";
  const std::string png = draw_plot(spec, series, PlotFormat::Png, scratch);
  std::error_code ec;
  fs::remove_all(scratch, ec);
  write_file_atomically(file, png);
}

}  // namespace

std::vector<fs::path> write_bench_plots(const fs::path& out_dir, const std::vector<BenchPoint>& points) {
  std::vector<fs::path> written;
  std::vector<std::string> scenes, runs;
  for (const BenchPoint& p : points) {
    if (std::find(scenes.begin(), scenes.end(), p.scene) == scenes.end()) scenes.push_back(p.scene);
    if (std::find(runs.begin(), runs.end(), p.run) == runs.end()) runs.push_back(p.run);
  }
  struct Metric {
    const char* file;
    const char* label;
    double BenchPoint::*field;
  };
  const Metric metrics[] = {{"psnr", "test PSNR (dB)", &BenchPoint::psnr},
                            {"ssim", "test SSIM", &BenchPoint::ssim},
                            {"iou", "distractor mask IoU", &BenchPoint::mask_iou}};
  for (const std::string& scene : scenes)
    for (const Metric& metric : metrics) {
      std::vector<PlotSeries> series;
      for (size_t r = 0; r < runs.size(); ++r) {
        const std::string& run = runs[r];
        PlotSeries s{run, {}, {}};
        for (const BenchPoint& p : points) {
          if (p.scene != scene || p.run != run) continue;
          if (metric.field == &BenchPoint::mask_iou && (!p.desplat || p.mask_iou < 0)) continue;
          s.x.push_back(p.train_seconds), s.y.push_back(p.*metric.field);
        }
        if (!s.x.empty()) series.push_back(s);
      }
      if (series.empty()) continue;
      const fs::path file = out_dir / (scene + "_" + metric.file + "_vs_time.png");
      write_plot(
          file,
          line_plot(scene + ": " + metric.label + " against training time", "training wall time (s)", metric.label),
          series);
      written.push_back(file);
    }
  // Final PSNR against clutter ratio, one series per run, over scenes that carry a ratio.
  std::vector<PlotSeries> clutter;
  for (size_t r = 0; r < runs.size(); ++r) {
    const std::string& run = runs[r];
    std::vector<std::pair<double, double>> xy;
    for (const std::string& scene : scenes) {
      const BenchPoint* last = nullptr;
      for (const BenchPoint& p : points)
        if (p.scene == scene && p.run == run && p.clutter_ratio >= 0 && (!last || p.step > last->step)) last = &p;
      if (last) xy.emplace_back(100 * last->clutter_ratio, last->psnr);
    }
    std::sort(xy.begin(), xy.end());
    PlotSeries s{run, {}, {}};
    for (const auto& [x, y] : xy) s.x.push_back(x), s.y.push_back(y);
    if (s.x.size() >= 2) clutter.push_back(s);
  }
  if (!clutter.empty()) {
    const fs::path file = out_dir / "psnr_vs_clutter.png";
    write_plot(file,
               line_plot("final test PSNR against clutter ratio", "cluttered training views (%)", "test PSNR (dB)"),
               clutter);
    written.push_back(file);
  }
  // The clutter summary: recovered fraction and mask IoU per DeSplat run against clutter.
  const std::vector<ClutterSummaryRow> summary = clutter_summary(points);
  if (!summary.empty()) {
    const fs::path csv = out_dir / "clutter_summary.csv";
    write_clutter_summary_csv(csv, summary);
    written.push_back(csv);
    std::vector<PlotSeries> recovered, iou;  // rows come by run, so each run is one series
    auto add_point = [](std::vector<PlotSeries>& all, const std::string& run, double x, double y) {
      if (all.empty() || all.back().label != run) all.push_back({run, {}, {}});
      all.back().x.push_back(x), all.back().y.push_back(y);
    };
    for (const ClutterSummaryRow& r : summary) {
      if (std::isfinite(r.recovered)) add_point(recovered, r.run, 100 * r.clutter_ratio, r.recovered);
      if (r.mask_iou >= 0) add_point(iou, r.run, 100 * r.clutter_ratio, r.mask_iou);
    }
    if (!recovered.empty()) {
      const fs::path file = out_dir / "recovered_vs_clutter.png";
      write_plot(file,
                 line_plot("recovered fraction (DeSplat − static-only) / (clean − static-only)",
                           "cluttered training views (%)", "recovered fraction"),
                 recovered);
      written.push_back(file);
    }
    if (!iou.empty()) {
      const fs::path file = out_dir / "iou_vs_clutter.png";
      write_plot(file,
                 line_plot("distractor mask IoU against clutter ratio", "cluttered training views (%)", "mask IoU"),
                 iou);
      written.push_back(file);
    }
  }
  return written;
}

}  // namespace desplat
