#include "fit/outlier_rounds.hpp"

#include <algorithm>
#include <cmath>

namespace robocal::vision::detail {

double outlier_limit(std::vector<double> inlier_d2, double sigmas) {
  const auto middle = inlier_d2.begin() + static_cast<long>(inlier_d2.size() / 2);
  std::nth_element(inlier_d2.begin(), middle, inlier_d2.end());
  // A median above 2 ln 2 means the sigmas are optimistic: the limit widens with it.
  const double spread = std::max(1.0, *middle / (2.0 * std::log(2.0)));
  return sigmas * sigmas * spread;
}

}  // namespace robocal::vision::detail
