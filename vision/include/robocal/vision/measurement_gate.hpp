#pragma once
// Plausibility of a session's board pose measurements. With the right board file, in-focus
// images and calibrated cameras, a board pose fits its detected corners to the detector's own
// noise: chi^2/dof near 1 (rendered sessions: 0.97-1.22). A board file that does not match the
// printed board (5 % tag size: median chi^2/dof ~14,000), wrong intrinsics or rig, or defocus
// push every pose far above that; images swapped between two poses, or a board that moved
// between the cameras' exposures, push single poses above it while the rest fit. Measurements
// that fail either test must not reach identification as if they were good.
#include <cstddef>
#include <string>
#include <vector>

namespace robocal::vision {

struct BoardFitGateOptions {
  // Largest plausible median chi^2/dof over the session (residuals 5x the detector's noise).
  double max_median_chi2_dof = 25.0;
  // A pose is inconsistent when its chi^2/dof exceeds both this and `pose_vs_median` times the
  // session's median (real cells fit worse than rendered ones, evenly over their poses).
  double max_pose_chi2_dof = 25.0;
  double pose_vs_median = 10.0;
};

struct BoardFitVerdict {
  bool plausible = true;                  // the session as a whole
  double median_chi2_dof = 0.0;           // over the poses given
  std::vector<std::size_t> inconsistent;  // indices of single poses that fail (session plausible)
  std::string reason;                     // plain words when !plausible
};

// `chi2_per_dof`: one entry per measured pose (chi^2 / degrees of freedom of its board fit).
BoardFitVerdict judge_board_fits(const std::vector<double>& chi2_per_dof,
                                 const BoardFitGateOptions& options = {});

// The chi^2/dof above which a single pose is inconsistent, given the session's median.
double inconsistent_pose_limit(double median_chi2_dof, const BoardFitGateOptions& options = {});

// Why pose `chi2_dof` is excluded, in words, given the session's median.
std::string inconsistent_pose_reason(double chi2_dof, double median_chi2_dof);

}  // namespace robocal::vision
