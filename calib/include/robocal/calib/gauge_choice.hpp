#pragma once
// Which confounded parameters to hold at nominal (the gauge) when the data determine only some
// combinations of the candidates. Pure numerics on linearised, whitened rows.
//
// The rank analysis (identifiability.hpp) finds how many parameters the data separate (r) and one
// base set: the order of a column-pivoted QR. Any other r columns that the data separate as well
// fit the data equally, but the parameters they leave at nominal are not at nominal in the real
// robot: their deviation moves the predictions between and around the measured points, and the
// estimated parameters absorb it only where it was measured. The gauge chosen here is the set of
// r columns whose estimator has the least expected squared prediction error over target rows
// (e.g. the predicted heights over the probed area), the held parameters' truths off nominal by
// their tolerances (probe_design.hpp, average_prediction_error_with_held: noise through the
// estimated set plus the held set's bias):
//   E[e²] = mean_i [ g_S M_SS⁻¹ g_Sᵀ + (g_S K − g_H) Σ_H (g_S K − g_H)ᵀ ],  K = M_SS⁻¹ M_SH.
// Eligible sets: r columns with an effect, containing `must_estimate`, that pass the analysis'
// test on the column-scaled Jacobian (greedy pivoting keeps every one with a part > tolerance
// outside the span of the others kept) and leave every other column within the tolerance of
// their span (so the analysis would hold exactly the rest). Search: every subset when there are
// at most `max_subsets`, else exchanges (one held for one estimated) from the given set while
// the error falls. Criteria within a relative `tie_tolerance` of each other are equal (
// the symmetric arms of a Delta give mirror-image sets whose criteria differ only in the last
// bits, differently on different machines); among equal ones the lexicographically first set of
// column indices wins, so the choice does not depend on rounding.
#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace robocal::calib {

struct GaugeOptions {
  double rank_tolerance = 1e-7;  // as IdentifiabilityOptions::rank_tolerance of the analysis
  std::size_t max_subsets = 20000;
  // The criterion: the held set's bias alone instead of noise plus bias.
  bool bias_only = false;
  // Relative difference below which two criteria count as equal (then the fixed rule decides).
  double tie_tolerance = 1e-6;
};

struct GaugeChoice {
  std::vector<std::size_t> estimated;   // ascending column indices
  std::vector<std::size_t> held;        // ascending: columns with an effect that are not estimated
  double expected_error = 0.0;          // the criterion at `estimated` (squared target units)
  double bias = 0.0;                    // its held-parameter part
  double initial_expected_error = 0.0;  // the criterion at the given set
  double initial_bias = 0.0;
  bool changed = false;       // `estimated` differs from the given set
  std::size_t evaluated = 0;  // eligible sets weighed
};

// `J`: whitened rows (measurement equations) × candidate columns; `targets`: whitened rows of the
// predicted quantities (same columns); `sigma`: tolerance per column (how far the truth may be
// from nominal); `initial`: the analysis' base set; `no_effect`: columns that change no
// measurement (held, never estimated; their bias is the same for every choice).
GaugeChoice choose_gauge(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets,
                         const Eigen::VectorXd& sigma, const std::vector<std::size_t>& initial,
                         const std::vector<std::size_t>& must_estimate,
                         const std::vector<std::size_t>& no_effect,
                         const GaugeOptions& options = {});

// The ordering the choice uses: `a` (the criterion of `set_a`) is less than `b` (of `set_b`) when
// it is lower by more than `relative_tolerance` of the larger, or, within that tolerance, when
// `set_a` is lexicographically before `set_b`. Non-finite criteria are never less.
bool gauge_criterion_less(double a, const std::vector<std::size_t>& set_a, double b,
                          const std::vector<std::size_t>& set_b, double relative_tolerance = 1e-6);

// The criterion above for one estimated set (every other column held).
double gauge_expected_error(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets,
                            const Eigen::VectorXd& sigma, const std::vector<std::size_t>& estimated,
                            bool bias_only = false);

// What the criterion needs of J and the targets, formed once for a search over many sets: JᵀJ
// and the targets' second moment are each a product over every row, far costlier than the
// criterion of one set.
struct GaugeProblem {
  Eigen::MatrixXd information;    // JᵀJ
  Eigen::MatrixXd target_moment;  // GᵀG / m (empty without targets)
};
GaugeProblem gauge_problem(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets);
// The same criterion as gauge_expected_error(J, targets, ...), to the last bit.
double gauge_expected_error(const GaugeProblem& problem, const Eigen::VectorXd& sigma,
                            const std::vector<std::size_t>& estimated, bool bias_only = false);

}  // namespace robocal::calib
