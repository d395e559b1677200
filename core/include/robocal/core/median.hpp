#pragma once
// The median of a list of values, for robust scales and thresholds.
#include <algorithm>
#include <cstddef>
#include <vector>

namespace robocal::core {

// The middle element of `values` (the upper one of an even count); `if_empty` when there is none.
inline double median(std::vector<double> values, double if_empty) {
  if (values.empty()) return if_empty;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace robocal::core
