#pragma once
// Where to measure so that predictions over a working area are best: an I-optimal
// (V-optimal) exact design. Pure numerics on linearised, whitened rows.
//
// Each candidate measurement c adds the whitened rows F_c (k_c × p) to the information matrix
// M = M₀ + Σ F_cᵀ F_c (M₀: what is known already, the data so far and priors). The quantity the
// user cares about is predicted at working-area points with rows g_i (1 × p, e.g. the bed height's
// derivative at a grid over the printed area); its variance there is g_i M⁻¹ g_iᵀ. The design
// minimises the average over the working area, trace(M⁻¹ GᵀG) / m, over `count` candidates:
// greedy from M₀, then exchange passes (swap a chosen for an unchosen candidate while the average
// falls; Fedorov's exchange restricted to the candidate list).
//
// Directions of the parameters that neither M₀ nor the chosen rows determine would make the
// average infinite. A ridge of `ridge` × (the largest diagonal of the candidates' total
// information) stands in for a very weak prior there, so the design first determines what the
// working area sees and, where that is impossible, leaves undetermined the directions the working
// area sees least (the held parameters' effect on predictions: the gauge's bias). Give a real
// prior in M₀ (1/σ² per parameter) to weigh that bias against the noise honestly: the criterion
// of an estimator that uses the prior (MAP).
//
// An estimator without priors instead estimates what the data separate and holds the rest at
// nominal (the gauge, identify's little-data rule). Its error at a target g is noise through the
// estimated set S plus the bias of the held set H, whose truths are off nominal by σ_H:
//   E[e²] = g_S M_SS⁻¹ g_Sᵀ + (g_S K − g_H) Σ_H (g_S K − g_H)ᵀ,   K = M_SS⁻¹ M_SH.
// DesignOptions::held (which parameters that estimator holds, given the information) makes the
// design minimise the average of that instead.
#include <Eigen/Core>

#include <cstddef>
#include <functional>
#include <vector>

namespace robocal::calib {

struct DesignOptions {
  bool allow_repeats = false;  // a candidate may be chosen more than once (repeated measurement)
  double ridge = 1e-9;         // relative, see above
  int max_exchange_passes = 50;
  // Which parameters the estimator holds at nominal given the chosen candidates' stacked rows
  // (see above; an estimator's own analysis of its rows, whose ties the information matrix alone
  // does not break the same way); unset = the variance criterion with the ridge. With it,
  // `held_sigma` (one per parameter) is how far each truth may be from nominal, and information0
  // should carry no prior.
  std::function<std::vector<std::size_t>(const Eigen::MatrixXd& chosen_rows)> held;
  Eigen::VectorXd held_sigma;
};

struct ExactDesign {
  std::vector<std::size_t> chosen;       // candidate indices (count of them, or fewer if too few)
  double average_variance = 0.0;         // trace(M⁻¹ GᵀG)/m at the design (with the ridge)
  double greedy_average_variance = 0.0;  // before the exchange passes
  int exchanges = 0;                     // accepted swaps
};

// The average prediction variance trace((M + ridge·I)⁻¹ GᵀG)/m (ridge absolute); +inf when the
// matrix is not positive definite.
double average_prediction_variance(const Eigen::MatrixXd& information,
                                   const Eigen::MatrixXd& targets, double ridge = 0.0);

// The average over the targets of E[e²] for the estimator that holds `held` at nominal (see
// above); +inf when the estimated block of `information` is not positive definite.
double average_prediction_error_with_held(const Eigen::MatrixXd& information,
                                          const Eigen::MatrixXd& targets,
                                          const std::vector<std::size_t>& held,
                                          const Eigen::VectorXd& held_sigma);

// The two parts of that error, from the targets' second moment GᵀG/m (target_second_moment), so
// that a search over many held sets forms the moment once: the noise's share and the held
// parameters' bias. variance is +inf when the estimated block is not positive definite.
struct HeldPredictionError {
  double variance = 0.0;
  double bias = 0.0;
};
Eigen::MatrixXd target_second_moment(const Eigen::MatrixXd& targets);
HeldPredictionError prediction_error_parts_with_held(const Eigen::MatrixXd& information,
                                                     const Eigen::MatrixXd& target_moment,
                                                     const std::vector<std::size_t>& held,
                                                     const Eigen::VectorXd& held_sigma);

// `candidate_rows[c]`: the whitened rows candidate c adds (each p columns); `targets`: the
// working-area rows (m × p); `information0`: p × p (empty = zeros).
ExactDesign i_optimal_design(const std::vector<Eigen::MatrixXd>& candidate_rows,
                             const Eigen::MatrixXd& targets, const Eigen::MatrixXd& information0,
                             std::size_t count, const DesignOptions& options = {});

}  // namespace robocal::calib
