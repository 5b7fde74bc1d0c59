// desplat_bench's report.html (see include/desplat/jobs/report.hpp): accuracy against training
// time per scene, then the final point of every run.
#include <algorithm>
#include <string>
#include <vector>

#include "desplat/io/atomic_file.hpp"
#include "desplat/jobs/report.hpp"
#include "jobs/report_page.hpp"
#include "jobs/text_format.hpp"

namespace desplat {

namespace fs = std::filesystem;
using namespace report;

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
    body += plot_frame(
        plotter.svg(line_plot(scene + ": test PSNR against training time", "training wall time [s]", "test PSNR [dB]"),
                    psnr),
        scene + " psnr");
    body += plot_frame(plotter.svg(line_plot(scene + ": distractor mask IoU against training time",
                                             "training wall time [s]", "mask IoU"),
                                   iou),
                       scene + " iou");
  }
  body +=
      "<h2>Final point of every run</h2>\n<table><tr><th>scene</th><th>run</th><th>steps</th><th>training "
      "time</th><th>test PSNR</th><th>SSIM</th><th>mask IoU</th><th>Gaussians static + distractor</th></tr>\n";
  for (const std::string& scene : scenes)
    for (const std::string& run : runs) {
      const BenchPoint* last = nullptr;
      for (const BenchPoint& b : points)
        if (b.scene == scene && b.run == run && (!last || b.step > last->step)) last = &b;
      if (!last) continue;
      body += "<tr><td>" + escape_html(scene) + "</td><td>" + escape_html(run) + "</td><td>" +
              std::to_string(last->step) + "</td><td>" + format_duration(last->train_seconds) + "</td><td>" +
              shown(last->psnr, 2) + " dB</td><td>" + shown(last->ssim, 4) + "</td><td>" +
              (last->mask_iou >= 0 ? shown(last->mask_iou, 3) : std::string("—")) + "</td><td>" +
              std::to_string(last->static_gaussians) + " + " + std::to_string(last->distractor_gaussians) +
              "</td></tr>\n";
    }
  body += "</table>\n<p>Every measured point: <code>bench.csv</code> in this folder.</p>\n";
  const std::string html = page_start("desplat benchmark report") +
                           row("machine", machine_text()).insert(0, "<table>\n") + "</table>\n" +
                           note_paragraph(plotter) + body + "</body></html>\n";
  ReportResult r{out_dir / "report.html", plotter.drawn(), plotter.note()};
  write_file_atomically(r.path, html);
  return r;
}

}  // namespace desplat
