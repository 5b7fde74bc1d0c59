// The clutter benchmark's summary (docs/BENCHMARKS.md, clutter): from desplat_bench's
// points on scenes that carry a clutter ratio, one row per DeSplat run and clutter level with
// how much of what clutter costs the baseline DeSplat wins back.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "desplat/jobs/bench_run.hpp"

namespace desplat {

struct ClutterSummaryRow {
  double clutter_ratio = 0;                              // share of training views cluttered, [0, 1]
  std::string run;                                       // the DeSplat run
  double psnr = 0, mask_iou = -1;                        // its final test PSNR [dB] and mask IoU (-1: no masks)
  double train_seconds = 0;                              // its training wall time [s]
  double static_only_psnr = 0, static_only_seconds = 0;  // the static-only run, same scene
  double clean_psnr = 0;                                 // the static-only run on the clutter-free scene
  // (psnr − static_only_psnr) / (clean_psnr − static_only_psnr); NaN when clutter does not
  // cost the baseline anything (clean_psnr ≤ static_only_psnr): nothing to recover.
  double recovered = 0;
};

// Final points (the last step of each run on each scene). The baseline is the grid's first
// run without distractors; scenes without a clutter ratio are skipped. Empty when the points
// hold no such run, no DeSplat run, or no clutter-free scene. Rows by run, then clutter ratio.
std::vector<ClutterSummaryRow> clutter_summary(const std::vector<BenchPoint>& points);

// clutter_summary.csv (atomically; an undefined recovered fraction is an empty cell).
void write_clutter_summary_csv(const std::filesystem::path& path, const std::vector<ClutterSummaryRow>& rows);

}  // namespace desplat
