// report.html: one self-contained page per trained model folder, a file a person can mail.
//
// Built from what the run left in the folder (metrics.json, config.json, renders/test/,
// renders/train/), so it can be written again for any finished model. It shows the run's
// summary (scene, what was modelled, Gaussian counts, time, memory, machine), every test view
// as ground truth | render with its PSNR/SSIM, the decomposition rows of the training views
// with their mask IoU, curves of loss, PSNR and Gaussian count against step and wall time, the
// median step's time breakdown, and the configuration.
//
// Images are inlined as base64 PNG. Plots come from gnuplot (Debian's gnuplot-nox, installed
// by scripts/install_deps.sh) as SVG with axes, ticks, legends and gnuplot's mouse script (the
// value under the pointer), each in an iframe of its own so the scripts' element ids cannot
// collide. Without gnuplot the page is written with a note in place of each plot. Nothing is
// fetched from a network when the page is opened.
//
// Temporary files (gnuplot's script and output) live in <model_dir>/.report_tmp and are
// removed; the page is written atomically.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "desplat/jobs/bench_run.hpp"

namespace desplat {

struct ReportResult {
  std::filesystem::path path;  // <model_dir>/report.html
  int plots = 0;               // plots drawn (0 when gnuplot is missing)
  std::string note;            // why plots are missing; empty when all were drawn
};

// Throws std::invalid_argument naming the file when metrics.json or config.json is missing or
// not valid, and ImageError/AtomicWriteError when a render cannot be read or the page written.
ReportResult write_report(const std::filesystem::path& model_dir);

// desplat_bench's page, <out_dir>/report.html: per scene, test PSNR (and mask IoU for DeSplat
// runs on scenes with masks) against training wall time, one curve per run, then the final
// point of every (scene, run) and every measured point as a table.
ReportResult write_bench_report(const std::filesystem::path& out_dir, const std::vector<BenchPoint>& points);

}  // namespace desplat
