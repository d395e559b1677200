#pragma once
// Correlated corner noise in the estimators (internal).
//
// Corners measured together (the four corners of a refined AprilTag, see CornerGroup in
// observations.hpp) have a joint covariance C. Their stacked reprojection residuals r are
// whitened by L^-1 with C = L L^T, so that |L^-1 r|^2 is the chi-square of the group and the
// Gauss-Newton information J^T C^-1 J accounts for the correlation.
#include "robocal/vision/observations.hpp"

#include <ceres/cost_function.h>
#include <Eigen/Core>

#include <memory>
#include <optional>
#include <vector>

namespace robocal::vision::detail {

// Wraps per-corner cost functions (2 unwhitened pixel residuals each, identical parameter
// blocks) into one residual block whitened by `whitening` (= L^-1, 2n x 2n).
class WhitenedGroupCost : public ceres::CostFunction {
 public:
  WhitenedGroupCost(std::vector<std::unique_ptr<ceres::CostFunction>> corners,
                    Eigen::MatrixXd whitening);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  std::vector<std::unique_ptr<ceres::CostFunction>> corners_;
  Eigen::MatrixXd whitening_;
};

// How the corners of one list (e.g. one camera frame or one calibration view) are grouped.
// groups[g] lists indices into the corner list and whitening[g] = L^-1 of their joint
// covariance (the sub-matrix of the CornerGroup for the members present). Corners in no group
// (or in a group whose covariance is unusable) are in `singles`.
struct CornerGrouping {
  std::vector<std::vector<size_t>> groups;
  std::vector<Eigen::MatrixXd> whitening;
  std::vector<size_t> singles;
};

// `ids[i]` is the corner id of entry i; `use[i]` false drops the entry (outlier, unknown id).
CornerGrouping group_corners(const std::vector<int>& ids, const std::vector<bool>& use,
                             const std::vector<CornerGroup>& groups);

}  // namespace robocal::vision::detail
