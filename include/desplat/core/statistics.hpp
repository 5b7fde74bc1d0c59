// Small order statistics shared by the layers above (evidence for --effects, timing reports).
#pragma once

#include <algorithm>
#include <vector>

namespace desplat {

// The median of `values` (taken by value: reordered in the copy), the upper one of the two
// middle values for an even count; 0 for no values.
inline double median(std::vector<double> values) {
  if (values.empty()) return 0;
  const auto mid = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace desplat
