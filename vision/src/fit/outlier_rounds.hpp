#pragma once
// The outlier rule of the fits with calibrated cameras (internal): rig calibration and pose
// measurement. Each corner is judged by the squared Mahalanobis distance of its pixel residual
// under its own 2x2 covariance; the limit is outlier_sigmas^2, widened by the inliers' robust
// spread when the given sigmas are too optimistic. Round by round the corners beyond it go and
// the fit is made again, until none goes.
//
// Intrinsic calibration keeps a rule of its own (calibrate/intrinsic_calibration.cpp): it judges
// residuals in pixels against their median absolute deviation.
#include <cstddef>
#include <vector>

namespace robocal::vision::detail {

struct OutlierRule {
  double sigmas = 5.0;  // a corner beyond this many of its own sigmas is rejected
  int max_rounds = 5;
  int min_inliers = 0;  // fewer left after a round: the rounds stop, saying so
};

// The rejection limit on d2 for one round: sigmas^2 times the spread of the inliers' d2 over a
// chi-square with 2 dof (whose median is 2 ln 2), never below 1.
double outlier_limit(std::vector<double> inlier_d2, double sigmas);

struct OutlierRoundsEnd {
  bool too_few_left = false;  // a round left fewer than OutlierRule::min_inliers
  std::size_t inliers_left = 0;
};

// Runs the rounds on a fit already made. `inlier_d2()` gives d2 of every current inlier at the
// current fit, in a fixed order; `reject(i)` marks the i-th of them an outlier; `refit(round)`
// fits again on the inliers left and returns false to end the rounds.
template <class InlierD2, class Reject, class Refit>
OutlierRoundsEnd run_outlier_rounds(const OutlierRule& rule, InlierD2 inlier_d2, Reject reject,
                                    Refit refit) {
  for (int round = 0; round < rule.max_rounds; ++round) {
    const std::vector<double> d2 = inlier_d2();
    if (d2.empty()) break;
    const double limit = outlier_limit(d2, rule.sigmas);
    std::size_t newly = 0;
    for (std::size_t i = 0; i < d2.size(); ++i) {
      if (d2[i] > limit) {
        reject(i);
        ++newly;
      }
    }
    if (newly == 0) break;
    const std::size_t left = d2.size() - newly;
    if (left < static_cast<std::size_t>(rule.min_inliers)) return {true, left};
    if (!refit(round)) break;
  }
  return {};
}

}  // namespace robocal::vision::detail
