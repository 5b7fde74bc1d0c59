// The clutter benchmark's summary (include/desplat/jobs/clutter_summary.hpp).
#include "desplat/jobs/clutter_summary.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include "desplat/io/atomic_file.hpp"

namespace desplat {

std::vector<ClutterSummaryRow> clutter_summary(const std::vector<BenchPoint>& points) {
  // The last point of every (scene, run).
  std::map<std::pair<std::string, std::string>, const BenchPoint*> last;
  std::string baseline;
  std::vector<std::string> desplat_runs;
  for (const BenchPoint& p : points) {
    if (p.clutter_ratio < 0) continue;
    const BenchPoint*& slot = last[{p.scene, p.run}];
    if (!slot || p.step > slot->step) slot = &p;
    if (!p.desplat && baseline.empty()) baseline = p.run;
    if (p.desplat && std::find(desplat_runs.begin(), desplat_runs.end(), p.run) == desplat_runs.end())
      desplat_runs.push_back(p.run);
  }
  const BenchPoint* clean = nullptr;
  for (const auto& [key, p] : last)
    if (key.second == baseline && p->clutter_ratio == 0) clean = p;
  std::vector<ClutterSummaryRow> rows;
  if (baseline.empty() || !clean) return rows;
  for (const std::string& run : desplat_runs) {
    std::vector<ClutterSummaryRow> of_run;
    for (const auto& [key, p] : last) {
      if (key.second != run) continue;
      const auto base = last.find({key.first, baseline});
      if (base == last.end()) continue;
      ClutterSummaryRow r;
      r.clutter_ratio = p->clutter_ratio, r.run = run;
      r.psnr = p->psnr, r.mask_iou = p->mask_iou, r.train_seconds = p->train_seconds;
      r.static_only_psnr = base->second->psnr, r.static_only_seconds = base->second->train_seconds;
      r.clean_psnr = clean->psnr;
      const double cost = r.clean_psnr - r.static_only_psnr;
      r.recovered = cost > 0 ? (r.psnr - r.static_only_psnr) / cost : NAN;
      of_run.push_back(r);
    }
    std::stable_sort(of_run.begin(), of_run.end(), [](const ClutterSummaryRow& a, const ClutterSummaryRow& b) {
      return a.clutter_ratio < b.clutter_ratio;
    });
    rows.insert(rows.end(), of_run.begin(), of_run.end());
  }
  return rows;
}

void write_clutter_summary_csv(const std::filesystem::path& path, const std::vector<ClutterSummaryRow>& rows) {
  std::ostringstream s;
  s.precision(6);
  s << "clutter_ratio,run,psnr,static_only_psnr,clean_psnr,recovered_fraction,mask_iou,train_seconds,"
       "static_only_seconds\n";
  for (const ClutterSummaryRow& r : rows) {
    s << r.clutter_ratio << "," << r.run << "," << r.psnr << "," << r.static_only_psnr << "," << r.clean_psnr << ",";
    if (std::isfinite(r.recovered)) s << r.recovered;
    s << "," << r.mask_iou << "," << r.train_seconds << "," << r.static_only_seconds << "\n";
  }
  write_file_atomically(path, s.str());
}

}  // namespace desplat
