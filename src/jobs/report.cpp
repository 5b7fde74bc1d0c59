// report.html from a model folder's files (see include/desplat/jobs/report.hpp).
#include "desplat/jobs/report.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>
#include <vector>

#include "desplat/io/atomic_file.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/eval/plot.hpp"
#include "desplat/io/colmap.hpp"
#include "desplat/io/ply.hpp"
#include "jobs/base64.hpp"
#include "jobs/text_format.hpp"
#include "jobs/splat_viewer.hpp"

namespace desplat {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument("cannot read " + path.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}


std::string escape_html(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

// shown() that says "inf" or "n/a" for values that are not numbers (a perfect PSNR, a missing key).
std::string shown(double v, int digits) {
  if (!std::isfinite(v)) return v > 0 ? "inf" : "n/a";
  return fixed(v, digits);
}

double number(const json& j, const char* key, double fallback = NAN) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : fallback;
}

std::string duration(double s) {
  if (!std::isfinite(s)) return "n/a";
  const long t = std::lround(s);
  char buf[48];
  if (t >= 3600) std::snprintf(buf, sizeof buf, "%ld h %02ld min", t / 3600, t / 60 % 60);
  else if (t >= 60) std::snprintf(buf, sizeof buf, "%ld min %02ld s", t / 60, t % 60);
  else std::snprintf(buf, sizeof buf, "%.1f s", s);
  return buf;
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) return line.substr(colon + 2);
    }
  return "unknown CPU";
}

// ---- Plots (eval/plot.hpp) ---------------------------------------------------------------------

struct Series {
  std::string label;
  std::vector<std::pair<double, double>> points;
};

// SVG plots for the page; a plot that cannot be drawn leaves a note instead of failing the run.
class Plotter {
 public:
  explicit Plotter(fs::path scratch) : scratch_(std::move(scratch)) {}
  ~Plotter() {
    std::error_code ec;
    fs::remove_all(scratch_, ec);
  }

  // The SVG's text, or "" when there is nothing to plot or it could not be drawn (note()).
  std::string svg(const PlotSpec& spec, const std::vector<Series>& series) {
    std::vector<PlotSeries> plot;
    for (const Series& s : series) {
      if (s.points.empty()) continue;
      PlotSeries p{s.label, {}, {}};
      for (const auto& [x, y] : s.points) p.x.push_back(x), p.y.push_back(y);
      plot.push_back(std::move(p));
    }
    if (plot.empty()) return "";
    PlotSpec sized = spec;
    sized.width = 620, sized.height = 340;
    try {
      std::string svg = draw_plot(sized, plot, PlotFormat::Svg, scratch_);
      ++drawn_;
      return svg;
    } catch (const std::exception& e) {  // PlotError, or no finite point
      note_ = e.what();
      return "";
    }
  }
  int drawn() const { return drawn_; }
  const std::string& note() const { return note_; }

 private:
  fs::path scratch_;
  std::string note_;
  int drawn_ = 0;
};

// An SVG in an iframe of its own (gnuplot's scripts use fixed element ids).
std::string plot_frame(const std::string& svg, const std::string& title) {
  if (svg.empty()) return "";
  std::string body = svg;
  if (body.rfind("<?xml", 0) == 0) body = body.substr(body.find("?>") + 2);
  return "<iframe class=\"plot\" title=\"" + escape_html(title) +
         "\" srcdoc=\"" + escape_html("<!DOCTYPE html><html><body style='margin:0'>" + body + "</body></html>") +
         "\"></iframe>\n";
}

// ---- Sections ----------------------------------------------------------------------------------

std::string png_img(const fs::path& file, const std::string& alt) {
  return "<img alt=\"" + escape_html(alt) + "\" src=\"data:image/png;base64," + base64(read_bytes(file)) + "\">";
}

std::string row(const std::string& key, const std::string& value) {
  return "<tr><th>" + escape_html(key) + "</th><td>" + escape_html(value) + "</td></tr>\n";
}

std::string summary(const json& m, const json& c) {
  const json scene = c.value("scene", json::object());
  const json cost = m.value("cost", json::object());
  const bool desplat = m.value("mode", "") == "desplat";
  std::string s = "<h2>Summary</h2>\n<table>\n";
  s += row("scene", scene.value("data_dir", std::string("?")) + " (downscale " +
                        std::to_string(scene.value("downscale", 1)) + ", " +
                        std::to_string(scene.value("train_views", json::array()).size()) + " training and " +
                        std::to_string(scene.value("test_views", json::array()).size()) + " test views" +
                        (scene.contains("masks_dir") ? ", masks from " + scene["masks_dir"].get<std::string>() : "") +
                        ")");
  s += row("effects modelled",
           desplat ? "static scene + per-view distractors (DeSplat); appearance and background are not modelled"
                   : "static scene only (the Splatfacto baseline, --static-only)");
  s += row("test PSNR / SSIM", std::isnan(number(m, "mean_psnr"))
                                   ? "no test views"
                                   : shown(number(m, "mean_psnr"), 2) + " dB / " + shown(number(m, "mean_ssim"), 4));
  s += row("Gaussians", std::to_string(m.value("gaussians", 0)) + " static + " +
                            std::to_string(cost.value("distractor_gaussians", 0)) + " distractor");
  s += row("steps", std::to_string(m.value("step", 0)));
  s += row("training time (this run)", duration(number(m, "wall_seconds_this_run")));
  s += row("peak memory", shown(number(m, "peak_memory_mb"), 0) + " MB");
  s += row("machine", cpu_model() + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads");
  const json& masks = m.contains("distractor_masks") ? m["distractor_masks"] : json();
  if (masks.is_object())
    s += row("distractor masks", "mean IoU " + shown(number(masks, "mean_iou"), 3) + " over " +
                                     std::to_string(masks.value("occluded_views", 0)) + " occluded training views");
  return s + "</table>\n";
}

std::string test_views(const json& m, const fs::path& dir) {
  std::string s = "<h2>Test views: ground truth | render</h2>\n";
  if (!m.contains("views") || m["views"].empty()) return s + "<p>No test views (the split left none).</p>\n";
  for (const json& v : m["views"]) {
    const std::string name = v.value("name", "");
    const fs::path file = dir / "renders" / "test" / fs::path(name).replace_extension(".png");
    s += "<figure>" + (fs::exists(file) ? png_img(file, name) : "<p>(no render)</p>") + "<figcaption>" +
         escape_html(name) + ": PSNR " + shown(number(v, "psnr"), 2) + " dB, SSIM " + shown(number(v, "ssim"), 4) +
         "</figcaption></figure>\n";
  }
  return s;
}

std::string decomposition(const json& m, const fs::path& dir) {
  const fs::path folder = dir / "renders" / "train";
  if (!fs::is_directory(folder)) return "";
  std::map<std::string, double> iou;
  if (m.contains("distractor_masks") && m["distractor_masks"].is_object())
    for (const json& v : m["distractor_masks"].value("views", json::array()))
      iou[fs::path(v.value("name", "")).replace_extension(".png").string()] = number(v, "iou");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(folder))
    if (e.path().extension() == ".png") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::string s = "<h2>Training views: truth | static | distractor | composite | distractor mask</h2>\n";
  for (const fs::path& f : files) {
    const auto it = iou.find(f.filename().string());
    s += "<figure>" + png_img(f, f.filename().string()) + "<figcaption>" + escape_html(f.filename().string()) +
         (it != iou.end() ? ": mask IoU " + shown(it->second, 3) : "") + "</figcaption></figure>\n";
  }
  return s;
}

// What structure from motion did, when this run started from photos (--images): how many were
// placed, each step tried, and every photo or file that was left out with its reason.
std::string structure_from_motion(const json& m) {
  const json& sfm = m.contains("sfm") ? m["sfm"] : json();
  if (!sfm.is_object()) return "";
  std::string s = "<h2>Structure from motion</h2>\n<table>\n";
  s += row("photos placed", std::to_string(sfm.value("registered", 0)) + " of " + std::to_string(sfm.value("photos", 0)) +
                                ", " + std::to_string(sfm.value("points", 0)) + " points, mean track length " +
                                shown(number(sfm, "mean_track_length"), 2) + ", mean reprojection error " +
                                shown(number(sfm, "mean_reprojection_error_px"), 2) + " px");
  s += row("cameras", sfm.value("cameras", std::string("?")));
  if (sfm.contains("matching")) s += row("matching", sfm.value("matching", std::string("?")));
  if (!sfm.value("warning", std::string()).empty()) s += row("warning", sfm["warning"].get<std::string>());
  s += "</table>\n<table><tr><th>step</th><th>photos placed</th><th>points</th><th>time</th><th>settings</th></tr>\n";
  for (const json& a : sfm.value("attempts", json::array()))
    s += "<tr><td>" + escape_html(a.value("step", "")) + "</td><td>" + std::to_string(a.value("registered", 0)) +
         "</td><td>" + std::to_string(a.value("points", 0)) + "</td><td>" + duration(number(a, "seconds")) +
         "</td><td>" + escape_html(a.value("settings", "")) + "</td></tr>\n";
  s += "</table>\n";
  const auto list = [&](const char* key, const char* name_key, const std::string& heading) {
    const json items = sfm.value(key, json::array());
    if (items.empty()) return;
    s += "<p>" + escape_html(heading) + "</p>\n<table>\n";
    for (const json& f : items) s += row(f.value(name_key, ""), f.value("reason", ""));
    s += "</table>\n";
  };
  list("unregistered_photos", "photo", "Photos structure from motion could not place (not trained on):");
  list("skipped_files", "file", "Files in the images folder that were not used:");
  return s;
}

std::string curves(const json& m, Plotter& plotter) {
  Series loss{"training loss", {}}, train_psnr{"training PSNR (composite)", {}}, test_psnr{"test PSNR", {}};
  Series statics{"static", {}}, distractors{"distractor", {}}, psnr_time{"training PSNR", {}},
      test_time{"test PSNR", {}}, count_time{"static Gaussians", {}};
  for (const json& h : m.value("history", json::array())) {
    const double step = number(h, "step"), t = number(h, "wall_seconds");
    const std::string kind = h.value("kind", "");
    if (kind == "training") {
      loss.points.push_back({step, number(h, "loss")});
      train_psnr.points.push_back({step, number(h, "psnr")});
      statics.points.push_back({step, number(h, "gaussians")});
      distractors.points.push_back({step, number(h, "distractor_gaussians")});
      psnr_time.points.push_back({t, number(h, "psnr")});
      count_time.points.push_back({t, number(h, "gaussians")});
    } else if (kind == "evaluation") {
      test_psnr.points.push_back({step, number(h, "mean_psnr")});
      test_time.points.push_back({t, number(h, "mean_psnr")});
    }
  }
  if (!std::isnan(number(m, "mean_psnr")) && !loss.points.empty()) {  // the final evaluation
    test_psnr.points.push_back({double(m.value("step", 0)), number(m, "mean_psnr")});
    test_time.points.push_back({number(m, "wall_seconds_this_run"), number(m, "mean_psnr")});
  }
  std::vector<Series> psnr_series{train_psnr}, time_series{psnr_time};
  if (!test_psnr.points.empty()) psnr_series.push_back(test_psnr), time_series.push_back(test_time);
  std::vector<Series> count_series{statics};
  if (m.value("mode", "") == "desplat") count_series.push_back(distractors);
  std::string s = "<h2>Curves</h2>\n";
  s += plot_frame(plotter.svg(line_plot("loss against step", "step", "loss"), {loss}), "loss");
  s += plot_frame(plotter.svg(line_plot("PSNR against step", "step", "PSNR [dB]"), psnr_series), "psnr");
  s += plot_frame(plotter.svg(line_plot("Gaussians against step", "step", "Gaussians"), count_series), "gaussians");
  s += plot_frame(plotter.svg(line_plot("PSNR against wall time", "wall time [s]", "PSNR [dB]"), time_series), "psnr-time");
  s += plot_frame(plotter.svg(line_plot("static Gaussians against wall time", "wall time [s]", "Gaussians"), {count_time}),
                  "gaussians-time");
  return s;
}

std::string step_breakdown(const json& m, Plotter& plotter) {
  const json t = m.value("median_step_seconds_full_resolution", json::object());
  if (!t.is_object() || t.value("steps_measured", 0) == 0)
    return "<h2>Time of a step</h2>\n<p>No step ran at full resolution (the resolution schedule had not reached "
           "it), so there is no breakdown.</p>\n";
  Series ms{"median milliseconds", {}};
  std::vector<std::string> labels;
  std::string table = "<table>\n";
  for (const char* part : {"forward", "backward", "loss", "optimizer_and_density", "distractor_branch"}) {
    const double v = 1000 * number(t, part, 0);
    ms.points.push_back({double(labels.size()), v});
    labels.push_back(part);
    table += row(part, shown(v, 1) + " ms");
  }
  table += row("total", shown(1000 * number(t, "total", 0), 1) + " ms (median over " +
                            std::to_string(t.value("steps_measured", 0)) + " full-resolution steps)");
  PlotSpec p = line_plot("median full-resolution step", "", "ms");
  p.bars = true, p.bar_labels = labels;
  return "<h2>Time of a step</h2>\n" + plot_frame(plotter.svg(p, {ms}), "step-time") + table + "</table>\n";
}

const char* kStyle = R"(<style>
body { font-family: sans-serif; margin: 2em; color: #222; max-width: 1400px; }
table { border-collapse: collapse; margin-bottom: 1em; }
th, td { text-align: left; padding: 0.2em 1em 0.2em 0; border-bottom: 1px solid #ddd; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; }
figure img { max-width: 100%; image-rendering: pixelated; min-width: 256px; }
iframe.plot { width: 640px; height: 360px; border: none; }
pre { background: #f6f6f6; padding: 1em; overflow-x: auto; }
.note { color: #a40; }
</style>)";

// Counts broken images and drawn plots once the page has loaded (for people: nothing; for the
// headless-browser test: data attributes on <body>).
const char* kSelfCheck = R"(<script>
window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img'), broken = 0;
  imgs.forEach(function (i) { if (!i.complete || i.naturalWidth === 0) broken++; });
  var frames = document.querySelectorAll('iframe.plot'), drawn = 0;
  frames.forEach(function (f) { var d = f.contentDocument; if (d && d.querySelector('svg path')) drawn++; });
  document.body.setAttribute('data-images', imgs.length);
  document.body.setAttribute('data-broken-images', broken);
  document.body.setAttribute('data-plots', drawn);
});
</script>)";

// The first test view's camera (else the first training view's), from the scene's COLMAP model,
// in the PLY's frame; nullopt when the scene cannot be read (moved since training).
std::optional<ViewerCamera> starting_camera(const json& config) {
  try {
    const json& scene = config.at("scene");
    const colmap::Model model = colmap::read_model(fs::path(scene.at("data_dir").get<std::string>()) / "sparse" / "0");
    std::vector<std::string> names = scene.value("test_views", std::vector<std::string>{});
    for (const std::string& n : scene.value("train_views", std::vector<std::string>{})) names.push_back(n);
    for (const std::string& name : names)
      for (const auto& [id, image] : model.images) {
        if (image.name != name) continue;
        const colmap::Camera& cam = model.cameras.at(image.camera_id);
        const std::string params = colmap::camera_model_info(cam.model).param_names;
        const bool one_focal = params.rfind("f,", 0) == 0;  // SIMPLE_*, RADIAL*, FOV: f, cx, cy, …
        ViewerCamera c;
        const auto [w, x, y, z] = image.qvec_wxyz;
        // World → camera, normalized as the scene loader does. GLM stores a matrix by columns,
        // so the transpose's storage is R_cw row-major, as ViewerCamera keeps it.
        const glm::dmat3 R_cw = glm::mat3_cast(glm::normalize(glm::dquat(w, x, y, z)));
        const glm::dmat3 R_cw_by_rows = glm::transpose(R_cw);
        std::copy_n(glm::value_ptr(R_cw_by_rows), 9, c.R.begin());
        c.t = image.tvec;
        c.fx = cam.params[0];
        c.fy = one_focal ? cam.params[0] : cam.params[1];
        c.cx = cam.params[one_focal ? 1 : 2];
        c.cy = cam.params[one_focal ? 2 : 3];
        c.width = int(cam.width), c.height = int(cam.height);
        return c;
      }
  } catch (const std::exception&) {  // no model to start from: the viewer frames the Gaussians
  }
  return std::nullopt;
}

std::string viewer(const fs::path& model_dir, const json& config) {
  const fs::path ply = model_dir / "point_cloud.ply";
  if (!fs::exists(ply)) return "";
  std::array<float, 3> bg{0, 0, 0};
  const json train = config.value("train", json::object());
  if (train.contains("eval_background")) bg = train["eval_background"].get<std::array<float, 3>>();
  return splat_viewer_section(read_gaussian_ply(ply), starting_camera(config), bg);
}

std::string page_start(const std::string& title) {
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + escape_html(title) +
         "</title>" + kStyle + kSelfCheck + "</head><body>\n<h1>" + escape_html(title) + "</h1>\n";
}

std::string note_paragraph(const Plotter& plotter) {
  return plotter.note().empty() ? "" : "<p class=\"note\">" + escape_html(plotter.note()) + "</p>\n";
}

}  // namespace

ReportResult write_bench_report(const fs::path& out_dir, const std::vector<BenchPoint>& points) {
  Plotter plotter(out_dir / ".report_tmp");
  std::vector<std::string> scenes, runs;
  for (const BenchPoint& p : points) {
    if (std::find(scenes.begin(), scenes.end(), p.scene) == scenes.end()) scenes.push_back(p.scene);
    if (std::find(runs.begin(), runs.end(), p.run) == runs.end()) runs.push_back(p.run);
  }
  std::string body = "<h2>Accuracy against training time</h2>\n";
  for (const std::string& scene : scenes) {
    std::vector<Series> psnr, iou;
    for (const std::string& run : runs) {
      Series p{run, {}}, m{run, {}};
      for (const BenchPoint& b : points) {
        if (b.scene != scene || b.run != run) continue;
        p.points.push_back({b.train_seconds, b.psnr});
        if (b.desplat && b.mask_iou >= 0) m.points.push_back({b.train_seconds, b.mask_iou});
      }
      psnr.push_back(p), iou.push_back(m);
    }
    body += plot_frame(plotter.svg(line_plot(scene + ": test PSNR against training time", "training wall time [s]",
                                             "test PSNR [dB]"), psnr), scene + " psnr");
    body += plot_frame(plotter.svg(line_plot(scene + ": distractor mask IoU against training time",
                                             "training wall time [s]", "mask IoU"), iou), scene + " iou");
  }
  body += "<h2>Final point of every run</h2>\n<table><tr><th>scene</th><th>run</th><th>steps</th><th>training "
          "time</th><th>test PSNR</th><th>SSIM</th><th>mask IoU</th><th>Gaussians static + distractor</th></tr>\n";
  for (const std::string& scene : scenes)
    for (const std::string& run : runs) {
      const BenchPoint* last = nullptr;
      for (const BenchPoint& b : points)
        if (b.scene == scene && b.run == run && (!last || b.step > last->step)) last = &b;
      if (!last) continue;
      body += "<tr><td>" + escape_html(scene) + "</td><td>" + escape_html(run) + "</td><td>" +
              std::to_string(last->step) + "</td><td>" + duration(last->train_seconds) + "</td><td>" +
              shown(last->psnr, 2) + " dB</td><td>" + shown(last->ssim, 4) + "</td><td>" +
              (last->mask_iou >= 0 ? shown(last->mask_iou, 3) : std::string("—")) + "</td><td>" +
              std::to_string(last->static_gaussians) + " + " + std::to_string(last->distractor_gaussians) +
              "</td></tr>\n";
    }
  body += "</table>\n<p>Every measured point: <code>bench.csv</code> in this folder.</p>\n";
  const std::string html = page_start("desplat benchmark report") +
                           row("machine", cpu_model() + ", " + std::to_string(std::thread::hardware_concurrency()) +
                                              " hardware threads")
                               .insert(0, "<table>\n") +
                           "</table>\n" + note_paragraph(plotter) + body + "</body></html>\n";
  ReportResult r{out_dir / "report.html", plotter.drawn(), plotter.note()};
  write_file_atomically(r.path, html);
  return r;
}

ReportResult write_report(const fs::path& model_dir) {
  const ModelFolder model(model_dir);
  const json metrics = model.read_metrics(), config = model.read_config_json();
  Plotter plotter(model_dir / ".report_tmp");
  std::string html = page_start("desplat training report: " + fs::absolute(model_dir).filename().string());
  std::string body = summary(metrics, config) + structure_from_motion(metrics) + viewer(model_dir, config) +
                     curves(metrics, plotter) +
                     step_breakdown(metrics, plotter) + test_views(metrics, model_dir) +
                     decomposition(metrics, model_dir);
  html += note_paragraph(plotter) + body + "<h2>Configuration (config.json)</h2>\n<pre>" + escape_html(config.dump(2)) + "</pre>\n</body></html>\n";
  ReportResult r{model_dir / "report.html", plotter.drawn(), plotter.note()};
  write_file_atomically(r.path, html);
  return r;
}

}  // namespace desplat
