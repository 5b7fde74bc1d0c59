// report.html for a trained model folder (see include/desplat/jobs/report.hpp): the summary,
// structure from motion, the 3D viewer, curves, the step's time, the views and the config.
#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/colmap.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/jobs/report.hpp"
#include "desplat/train/effects.hpp"
#include "jobs/report_page.hpp"
#include "jobs/splat_viewer.hpp"
#include "jobs/text_format.hpp"

namespace desplat {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace report;

// The effects the run recorded it modelled: metrics.json's effects.chosen, else config.json's
// run.effects (Effects::to_string text); a folder that records neither is read by its mode.
Effects recorded_effects(const json& m, const json& c) {
  std::string text;
  if (m.contains("effects") && m["effects"].is_object()) text = m["effects"].value("chosen", std::string());
  if (text.empty() && c.contains("run") && c["run"].is_object()) text = c["run"].value("effects", std::string());
  if (text.empty()) text = m.value("mode", "") == "desplat" ? "distractors" : "none";
  return Effects::parse(text);
}

// "static scene + per-view distractors (DeSplat); appearance and background are not modelled",
// and how the set was chosen when --effects auto chose it.
std::string effects_modelled(const json& m, const json& c) {
  Effects e;
  try {
    e = recorded_effects(m, c);
  } catch (const std::exception& error) {  // a hand-edited file: say so rather than guess
    return std::string("unreadable (") + error.what() + ")";
  }
  std::string text;
  if (!e.distractors && !e.appearance && !e.background) {
    text = "static scene only (the Splatfacto baseline)";
  } else {
    text = "static scene";
    std::vector<std::string> off;
    const auto part = [&](bool on, const char* what, const char* name) {
      if (on)
        text += std::string(" + ") + what;
      else
        off.push_back(name);
    };
    part(e.distractors, "per-view distractors (DeSplat)", "distractors");
    part(e.appearance, "per-image appearance (exposure and colour)", "appearance");
    part(e.background, "learned background (a colour per ray direction)", "background");
    if (off.size() == 1) text += "; " + off[0] + (off[0] == "distractors" ? " are" : " is") + " not modelled";
    if (off.size() == 2) text += "; " + off[0] + " and " + off[1] + " are not modelled";
  }
  const json by = m.contains("effects") && m["effects"].is_object() ? m["effects"].value("by", json()) : json();
  if (by == "auto") text += " (chosen by --effects auto)";
  return text;
}

std::string summary(const json& m, const json& c) {
  const json scene = c.value("scene", json::object());
  const json cost = m.value("cost", json::object());
  std::string s = "<h2>Summary</h2>\n<table>\n";
  s += row("scene",
           scene.value("data_dir", std::string("?")) + " (downscale " + std::to_string(scene.value("downscale", 1)) +
               ", " + std::to_string(scene.value("train_views", json::array()).size()) + " training and " +
               std::to_string(scene.value("test_views", json::array()).size()) + " test views" +
               (scene.contains("masks_dir") ? ", masks from " + scene["masks_dir"].get<std::string>() : "") + ")");
  s += row("effects modelled", effects_modelled(m, c));
  s += row("test PSNR / SSIM", std::isnan(number(m, "mean_psnr"))
                                   ? "no test views"
                                   : shown(number(m, "mean_psnr"), 2) + " dB / " + shown(number(m, "mean_ssim"), 4));
  s += row("Gaussians", std::to_string(m.value("gaussians", 0)) + " static + " +
                            std::to_string(cost.value("distractor_gaussians", 0)) + " distractor");
  s += row("steps", std::to_string(m.value("step", 0)));
  s += row("training time (this run)", format_duration(number(m, "wall_seconds_this_run")));
  s += row("peak memory", shown(number(m, "peak_memory_mb"), 0) + " MB");
  s += row("machine", machine_text());
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
  s += row("photos placed", std::to_string(sfm.value("registered", 0)) + " of " +
                                std::to_string(sfm.value("photos", 0)) + ", " + std::to_string(sfm.value("points", 0)) +
                                " points, mean track length " + shown(number(sfm, "mean_track_length"), 2) +
                                ", mean reprojection error " + shown(number(sfm, "mean_reprojection_error_px"), 2) +
                                " px");
  s += row("cameras", sfm.value("cameras", std::string("?")));
  if (sfm.contains("matching")) s += row("matching", sfm.value("matching", std::string("?")));
  // The capture's evidence and the mapper it chose (CaptureEvidence, desplat/sfm/sfm.hpp), and the
  // time each stage took.
  const json& capture = sfm.contains("capture") ? sfm["capture"] : json();
  if (capture.is_object() && capture.contains("summary")) s += row("capture", capture.value("summary", ""));
  if (!sfm.value("mapper", std::string()).empty()) s += row("mapper", sfm["mapper"].get<std::string>());
  if (!sfm.value("escalation_stopped", std::string()).empty())
    s += row("stopped early", sfm["escalation_stopped"].get<std::string>());
  const json& stages = sfm.contains("stage_seconds") ? sfm["stage_seconds"] : json();
  if (stages.is_object())
    s += row("time by stage", "features " + format_duration(number(stages, "extract")) + ", matching " +
                                  format_duration(number(stages, "match")) + ", evidence " +
                                  format_duration(number(stages, "evidence")) + ", mapping " +
                                  format_duration(number(stages, "map")) + "; " +
                                  format_duration(number(sfm, "seconds")) + " in all");
  if (!sfm.value("warning", std::string()).empty()) s += row("warning", sfm["warning"].get<std::string>());
  s += "</table>\n<table><tr><th>step</th><th>photos placed</th><th>points</th><th>time</th><th>settings</th></tr>\n";
  for (const json& a : sfm.value("attempts", json::array()))
    s += "<tr><td>" + escape_html(a.value("step", "")) + "</td><td>" + std::to_string(a.value("registered", 0)) +
         "</td><td>" + std::to_string(a.value("points", 0)) + "</td><td>" + format_duration(number(a, "seconds")) +
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
  s += plot_frame(plotter.svg(line_plot("PSNR against wall time", "wall time [s]", "PSNR [dB]"), time_series),
                  "psnr-time");
  s += plot_frame(
      plotter.svg(line_plot("static Gaussians against wall time", "wall time [s]", "Gaussians"), {count_time}),
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

}  // namespace

ReportResult write_report(const fs::path& model_dir) {
  const ModelFolder model(model_dir);
  const json metrics = model.read_metrics(), config = model.read_config_json();
  Plotter plotter(model_dir / ".report_tmp");
  std::string html = page_start("desplat training report: " + fs::absolute(model_dir).filename().string());
  std::string body = summary(metrics, config) + structure_from_motion(metrics) + viewer(model_dir, config) +
                     curves(metrics, plotter) + step_breakdown(metrics, plotter) + test_views(metrics, model_dir) +
                     decomposition(metrics, model_dir);
  html += note_paragraph(plotter) + body + "<h2>Configuration (config.json)</h2>\n<pre>" + escape_html(config.dump(2)) +
          "</pre>\n</body></html>\n";
  ReportResult r{model_dir / "report.html", plotter.drawn(), plotter.note()};
  write_file_atomically(r.path, html);
  return r;
}

}  // namespace desplat
