#pragma once
// A posteriori measurement noise per observation type, and the residual covariance the outlier
// test needs: pure functions over the whitened identification Jacobian and residuals.
//
// Why: the σ a user types (or a detector reports) is often a guess. After the fit the residuals
// say how large the noise really was, per observation type (heights, distances, points, pose
// position / rotation, pixels). Estimating it changes every uncertainty the engine reports:
// with a stated noise 5× too large every σ, interval and predicted accuracy is 5× pessimistic.
//
// Method (variance-component estimation, Förstner's iteration): rows are whitened by their
// stated noise, so each type g has an unknown scale s_g (1 = stated noise right). With H the hat
// matrix of the whitened, reweighted problem, the redundancy number of a row is q_i = 1 − h_ii
// (how much of that row's noise stays in its residual; Σ q_i = m − n) and
//   s_g² ← s_g² · Σ_{i∈g} r̃_i² / Σ_{i∈g} q_i        (r̃ = residual reweighted by the current s)
// iterated until the scales settle. Confidence: Σ r̃²/s² ~ χ² with r_g = Σ q_i degrees of freedom,
// which gives the interval of s_g. Rows without a group (−1: priors) keep scale 1.
//
// Normalised residuals r̃_i / √q_i have unit variance whatever the mix of σ and leverage: the
// robust scale (1.4826 · median |normalised residual|) and the per-pose outlier test use them
// (pose_residual_covariance below), never the raw whitened residuals, whose spread shrinks on
// rows that dominate the estimate.
#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::calib {

struct NoiseGroup {
  std::string type;           // "point", "pose position", "probe height", "distance", ...
  std::string unit;           // of stated_sigma: "m", "rad", "px"
  std::size_t rows = 0;       // residual rows of this type
  double stated_sigma = 0.0;  // median σ the data stated for these rows (unit)
  double redundancy = 0.0;    // Σ q_i over the rows (degrees of freedom of the estimate)
  bool estimable = false;     // redundancy ≥ 1: the residuals carry noise information
  double scale = 1.0;         // σ̂ / σ_stated (1 when not estimable)
  double scale_low = 1.0;     // 95 % interval of the scale (χ² with `redundancy` dof)
  double scale_high = 1.0;
  double robust_scale = 1.0;  // 1.4826 · median |normalised residual| · scale (outlier-proof)
  double estimated_sigma() const { return scale * stated_sigma; }
};

struct NoiseEstimate {
  std::vector<NoiseGroup> groups;
  Eigen::VectorXd row_scale;   // per row: the scale of its group (1 for rows without a group)
  Eigen::VectorXd redundancy;  // per row: q_i at the final weights
  // (J̃ᵀJ̃)⁻¹ of the reweighted problem (rows divided by row_scale): the parameter covariance when
  // the estimated noise is applied; columns as in J.
  Eigen::MatrixXd normal_inverse;
  int iterations = 0;
  bool ok = false;      // false when J is rank deficient or empty (message says why)
  std::string message;  // plain words
};

// `row_group[i]` ∈ [0, groups.size()) or −1; `groups` carry type, unit, stated_sigma (rows and
// the estimates are filled here). J must have full column rank.
NoiseEstimate estimate_noise(const Eigen::MatrixXd& whitened_jacobian,
                             const Eigen::VectorXd& whitened_residuals,
                             const std::vector<int>& row_group, std::vector<NoiseGroup> groups,
                             int max_iterations = 50);

// Covariance of the residuals of a block of rows (one pose): I − J_b C J_bᵀ for rows that took
// part in the fit, I + J_b C J_bᵀ for rows that did not (a prediction error), with C the
// normal_inverse above and J_b the block's rows already divided by their row scale.
Eigen::MatrixXd pose_residual_covariance(const Eigen::MatrixXd& block_jacobian,
                                         const Eigen::MatrixXd& normal_inverse, bool in_fit);

}  // namespace robocal::calib
