// The batch rules (docs/METHOD.md §6, batches).
#include "desplat/train/batch.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace desplat {

LearningRates batch_learning_rates(LearningRates lr, int views) {
  if (views < 1) throw std::logic_error("batch_learning_rates: a batch holds at least one view");
  if (views == 1) return lr;
  const float scale = float(std::sqrt(double(views)));
  for (const ParamGroupInfo& info : kParamGroupTable) lr.*info.rate *= scale;
  lr.colors_rest *= scale;  // the higher SH bands' rate, beside the table's DC rate
  return lr;
}

int64_t batch_event(int64_t first, int views, int64_t every) {
  if (every < 1 || views < 1) throw std::logic_error("batch_event: the period and the batch must be at least 1");
  const int64_t next = (first + every - 1) / every * every;  // the first multiple ≥ first
  return next < first + views ? next : -1;
}

void add_gradients(RasterGradients& sum, const RasterGradients& g) {
  for (const ParamGroupInfo& info : kParamGroupTable) {
    std::vector<float>& s = sum.*info.grads;
    const std::vector<float>& x = g.*info.grads;
    if (s.size() != x.size())
      throw std::logic_error(std::string("add_gradients: the ") + info.name + " gradients differ in size");
    const int64_t n = int64_t(s.size());
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; ++i) s[size_t(i)] += x[size_t(i)];
  }
}

}  // namespace desplat
