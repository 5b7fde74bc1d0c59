// The batch rules (docs/METHOD.md §6, batches).
#include "desplat/train/batch.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

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

namespace {
// The view tree's sum of the entries `at` (positions into views, in draw order), whose view
// indices agree below `bit`.
int tree_sum(std::span<const int> views, std::vector<int> at, int bit, const std::function<void(int, int)>& add) {
  const bool one_view =
      std::all_of(at.begin(), at.end(), [&](int e) { return views[size_t(e)] == views[size_t(at[0])]; });
  if (one_view) {
    for (size_t k = 1; k < at.size(); ++k) add(at[0], at[k]);
    return at[0];
  }
  std::vector<int> even, odd;
  for (int e : at) (views[size_t(e)] >> bit & 1 ? odd : even).push_back(e);
  if (even.empty()) return tree_sum(views, std::move(odd), bit + 1, add);
  if (odd.empty()) return tree_sum(views, std::move(even), bit + 1, add);
  const int into = tree_sum(views, std::move(even), bit + 1, add);
  add(into, tree_sum(views, std::move(odd), bit + 1, add));
  return into;
}
}  // namespace

int sum_in_view_tree(std::span<const int> views, const std::function<void(int into, int from)>& add) {
  if (views.empty()) return -1;
  for (int v : views)
    if (v < 0) throw std::invalid_argument("sum_in_view_tree: a view index is negative");
  std::vector<int> all(views.size());
  for (size_t k = 0; k < all.size(); ++k) all[k] = int(k);
  return tree_sum(views, std::move(all), 0, add);
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
