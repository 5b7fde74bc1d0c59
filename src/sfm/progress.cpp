// Progress lines for people: what describe() and terminal_progress() print (sfm.hpp).
#include <memory>
#include <sstream>

#include "desplat/core/stopwatch.hpp"
#include "sfm/progress.hpp"

namespace desplat::sfm {

std::string describe(const SfmProgress& p) {
  std::ostringstream s;
  const auto count = [&](int done, int total) {
    s << done;
    if (total > 0) s << "/" << total;
  };
  switch (p.stage) {
    case SfmStage::Extract:
      s << "extracting features: image ";
      count(p.done, p.total);
      break;
    case SfmStage::Match:
      s << "matching: " << p.unit << " ";
      count(p.done, p.total);
      break;
    case SfmStage::Map:
      s << "mapping: ";
      if (p.model > 1) s << "model " << p.model << ", ";
      s << "registered ";
      count(p.done, p.total);
      s << " photos";
      break;
  }
  if (p.finished) s << ", done";
  return s.str();
}

ProgressFn terminal_progress(std::FILE* out, bool is_tty, double plain_interval_s) {
  struct State {
    bool any = false;
    SfmStage stage = SfmStage::Extract;
    Stopwatch since_last;
  };
  auto state = std::make_shared<State>();
  return [out, is_tty, plain_interval_s, state](const SfmProgress& p) {
    const bool new_stage = !state->any || p.stage != state->stage;
    const double interval = is_tty ? 0.1 : plain_interval_s;
    if (!new_stage && !p.finished && state->since_last.seconds() < interval) return;
    state->any = true, state->stage = p.stage;
    state->since_last.restart();
    if (is_tty)
      std::fprintf(out, "\r\033[K%s%s", describe(p).c_str(), p.finished ? "\n" : "");
    else
      std::fprintf(out, "%s\n", describe(p).c_str());
    std::fflush(out);
  };
}

}  // namespace desplat::sfm
