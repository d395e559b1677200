#include "robocal/vision/measurement_gate.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>

namespace robocal::vision {

BoardFitVerdict judge_board_fits(const std::vector<double>& chi2_per_dof,
                                 const BoardFitGateOptions& options) {
  BoardFitVerdict v;
  if (chi2_per_dof.empty()) {
    return v;  // nothing measured: the stage says so itself
  }
  std::vector<double> sorted = chi2_per_dof;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t n = sorted.size();
  v.median_chi2_dof = n % 2 == 1 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  if (!(v.median_chi2_dof <= options.max_median_chi2_dof)) {  // NaN fails too
    v.plausible = false;
    v.reason = fmt::format(
        "the board poses do not fit their detected corners: median chi2/dof {:.0f} over {} poses "
        "(corner residuals {:.0f}x the detector's noise; plausible up to {:.0f}). Likely: the "
        "end-effector board's file does not match the printed board (its cols or rows, tag "
        "size or spacing, a print scaled by the printer), wrong camera intrinsics or rig, or "
        "images out of focus",
        v.median_chi2_dof, n, std::sqrt(v.median_chi2_dof), options.max_median_chi2_dof);
    return v;
  }
  const double pose_limit = inconsistent_pose_limit(v.median_chi2_dof, options);
  for (std::size_t i = 0; i < chi2_per_dof.size(); ++i) {
    if (!(chi2_per_dof[i] <= pose_limit)) {
      v.inconsistent.push_back(i);
    }
  }
  return v;
}

double inconsistent_pose_limit(double median_chi2_dof, const BoardFitGateOptions& options) {
  return std::max(options.max_pose_chi2_dof, options.pose_vs_median * median_chi2_dof);
}

std::string inconsistent_pose_reason(double chi2_dof, double median_chi2_dof) {
  return fmt::format(
      "board fit chi2/dof {:.0f} while the session's median is {:.1f}: the images disagree about "
      "where the board is (images swapped with another pose, or the board moved between the "
      "cameras' exposures)",
      chi2_dof, median_chi2_dof);
}

}  // namespace robocal::vision
