// Compares two desplat_train output folders: the one-process run and the multi-rank run of
// the same job (tests/mpi/train_ranks.sh). Usage:
//   compare_models ONE_PROCESS_OUT RANKS_OUT MAX_PSNR_DB MAX_COUNT_SHARE MAX_PARAM_DIFF
// Passes (exit 0) when the static Gaussian counts differ by at most MAX_COUNT_SHARE of the
// one-process count, the distractor counts likewise, the mean test PSNRs by at most
// MAX_PSNR_DB, and — when the counts are equal — every static parameter by at most
// MAX_PARAM_DIFF (absolute, in the PLY's units; 0 asks for the same bits). Prints the figures.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "desplat/io/json_text.hpp"
#include "desplat/io/ply.hpp"

namespace fs = std::filesystem;
using desplat::GaussianSet;

namespace {

nlohmann::json metrics_of(const fs::path& out) {
  std::ifstream in(out / "metrics.json");
  if (!in) throw std::runtime_error("no metrics.json in " + out.string());
  return desplat::parse_json_bounded(in, (out / "metrics.json").string());
}

double max_difference(const GaussianSet& a, const GaussianSet& b) {
  double worst = 0;
  auto scan = [&](const std::vector<float>& x, const std::vector<float>& y) {
    if (x.size() != y.size()) {
      worst = INFINITY;
      return;
    }
    for (size_t i = 0; i < x.size(); ++i) worst = std::max(worst, std::fabs(double(x[i]) - double(y[i])));
  };
  scan(a.means, b.means), scan(a.log_scales, b.log_scales), scan(a.quats, b.quats);
  scan(a.opacity_logits, b.opacity_logits), scan(a.colors, b.colors);
  return worst;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 6) {
    std::fprintf(stderr, "usage: compare_models ONE RANKS MAX_PSNR_DB MAX_COUNT_SHARE MAX_PARAM_DIFF\n");
    return 2;
  }
  try {
    const fs::path one = argv[1], ranks = argv[2];
    const double max_psnr = std::atof(argv[3]), max_share = std::atof(argv[4]), max_param = std::atof(argv[5]);
    const GaussianSet a = desplat::read_gaussian_ply(one / "point_cloud.ply");
    const GaussianSet b = desplat::read_gaussian_ply(ranks / "point_cloud.ply");
    const nlohmann::json ma = metrics_of(one), mb = metrics_of(ranks);
    const double psnr_a = ma.at("mean_psnr").get<double>(), psnr_b = mb.at("mean_psnr").get<double>();
    const double da = ma.at("cost").at("distractor_gaussians").get<double>(),
                 db = mb.at("cost").at("distractor_gaussians").get<double>();
    const double count_share = std::fabs(double(a.size()) - double(b.size())) / double(std::max<size_t>(1, a.size()));
    const double distractor_share = std::fabs(da - db) / std::max(1.0, da);
    const double param = a.size() == b.size() ? max_difference(a, b) : INFINITY;
    std::printf(
        "static Gaussians %zu vs %zu (%.4f %%), distractors %.0f vs %.0f (%.4f %%), test PSNR %.4f vs %.4f dB "
        "(%.4f dB), largest parameter difference %.3g\n",
        a.size(), b.size(), 100 * count_share, da, db, 100 * distractor_share, psnr_a, psnr_b,
        std::fabs(psnr_a - psnr_b), param);
    const bool ok = count_share <= max_share && distractor_share <= max_share &&
                    std::fabs(psnr_a - psnr_b) <= max_psnr && (a.size() != b.size() || param <= max_param);
    std::printf("%s\n", ok ? "models agree" : "models DIFFER beyond the tolerance");
    return ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "compare_models: %s\n", e.what());
    return 2;
  }
}
