#include "robocal/calib/gauge_choice.hpp"

#include "robocal/calib/probe_design.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace robocal::calib {

namespace {

std::vector<std::size_t> complement(std::size_t p, const std::vector<std::size_t>& estimated) {
  std::vector<std::size_t> held;
  for (std::size_t j = 0; j < p; ++j)
    if (std::find(estimated.begin(), estimated.end(), j) == estimated.end()) held.push_back(j);
  return held;
}

// The analysis' test on the column-scaled (and row-compressed) Jacobian R: greedy pivoting over
// `set` keeps every column (each has a part > tolerance outside the span of those kept before
// it), and every column of `others` lies within the tolerance of the set's span.
bool separates_like_the_analysis(const Eigen::MatrixXd& R, const std::vector<std::size_t>& set,
                                 const std::vector<std::size_t>& others, double tolerance) {
  Eigen::MatrixXd S(R.rows(), static_cast<Eigen::Index>(set.size()));
  for (std::size_t k = 0; k < set.size(); ++k)
    S.col(static_cast<Eigen::Index>(k)) = R.col(static_cast<Eigen::Index>(set[k]));
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(S);
  const auto n = static_cast<Eigen::Index>(set.size());
  if (n > R.rows()) return false;
  for (Eigen::Index k = 0; k < n; ++k)
    if (std::abs(qr.matrixQR()(k, k)) <= tolerance) return false;
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(R.rows(), n);
  for (std::size_t j : others) {
    const Eigen::VectorXd a = R.col(static_cast<Eigen::Index>(j));
    if ((a - Q * (Q.transpose() * a)).norm() > tolerance) return false;
  }
  return true;
}

}  // namespace

bool gauge_criterion_less(double a, const std::vector<std::size_t>& set_a, double b,
                          const std::vector<std::size_t>& set_b, double relative_tolerance) {
  if (!std::isfinite(a)) return false;
  if (!std::isfinite(b)) return true;
  const double scale = std::max(std::abs(a), std::abs(b));
  if (std::abs(a - b) > relative_tolerance * scale) return a < b;
  return set_a < set_b;  // equal up to rounding: the lexicographically first set
}

GaugeProblem gauge_problem(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets) {
  GaugeProblem problem;
  problem.information = J.transpose() * J;
  if (targets.rows() > 0) problem.target_moment = target_second_moment(targets);
  return problem;
}

double gauge_expected_error(const GaugeProblem& problem, const Eigen::VectorXd& sigma,
                            const std::vector<std::size_t>& estimated, bool bias_only) {
  if (problem.target_moment.size() == 0) return 0.0;
  const auto p = static_cast<std::size_t>(problem.information.cols());
  const std::vector<std::size_t> held = complement(p, estimated);
  const HeldPredictionError parts =
      prediction_error_parts_with_held(problem.information, problem.target_moment, held, sigma);
  const auto finite_or_inf = [](double t) {
    return std::isfinite(t) ? t : std::numeric_limits<double>::infinity();
  };
  const double total = finite_or_inf(parts.variance + parts.bias);
  if (!bias_only) return total;
  // The noise's share alone is what the criterion is with every held sigma zero; subtracted
  // from the total as that, so the bias carries the total's rounding.
  return total - finite_or_inf(parts.variance + 0.0);
}

double gauge_expected_error(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets,
                            const Eigen::VectorXd& sigma, const std::vector<std::size_t>& estimated,
                            bool bias_only) {
  return gauge_expected_error(gauge_problem(J, targets), sigma, estimated, bias_only);
}

GaugeChoice choose_gauge(const Eigen::MatrixXd& J, const Eigen::MatrixXd& targets,
                         const Eigen::VectorXd& sigma, const std::vector<std::size_t>& initial,
                         const std::vector<std::size_t>& must_estimate,
                         const std::vector<std::size_t>& no_effect, const GaugeOptions& options) {
  const auto p = static_cast<std::size_t>(J.cols());
  if (targets.cols() != J.cols() || static_cast<std::size_t>(sigma.size()) != p)
    throw std::invalid_argument("choose_gauge: targets and sigma must have one column per column");
  for (std::size_t j : initial)
    if (j >= p) throw std::invalid_argument("choose_gauge: column index out of range");

  // Column scaling and row compression as in the analysis.
  Eigen::MatrixXd scaled = J;
  for (Eigen::Index j = 0; j < J.cols(); ++j) {
    const double n = J.col(j).norm();
    if (n > 0.0) scaled.col(j) /= n;
  }
  Eigen::MatrixXd R = scaled;
  if (scaled.rows() > scaled.cols()) {
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(scaled);
    R = qr.matrixQR().topRows(scaled.cols()).triangularView<Eigen::Upper>();
  }

  std::vector<std::size_t> eligible;  // columns with an effect
  for (std::size_t j = 0; j < p; ++j)
    if (std::find(no_effect.begin(), no_effect.end(), j) == no_effect.end()) eligible.push_back(j);
  const std::size_t r = initial.size();

  const GaugeProblem problem = gauge_problem(J, targets);
  auto value = [&](const std::vector<std::size_t>& est) {
    return gauge_expected_error(problem, sigma, est, options.bias_only);
  };
  auto admissible = [&](const std::vector<std::size_t>& est) {
    for (std::size_t m : must_estimate)
      if (std::find(est.begin(), est.end(), m) == est.end()) return false;
    std::vector<std::size_t> others;
    for (std::size_t j : eligible)
      if (std::find(est.begin(), est.end(), j) == est.end()) others.push_back(j);
    return separates_like_the_analysis(R, est, others, options.rank_tolerance);
  };

  GaugeChoice choice;
  choice.estimated = initial;
  std::sort(choice.estimated.begin(), choice.estimated.end());
  choice.initial_expected_error = value(choice.estimated);
  choice.initial_bias = gauge_expected_error(problem, sigma, choice.estimated, /*bias_only=*/true);
  double best = choice.initial_expected_error;
  // Criteria equal up to rounding (a Delta's three arms are symmetric: mirror-image sets differ
  // in the last bits, differently on different machines) are a tie, broken by the fixed rule of
  // gauge_criterion_less, so the choice does not follow the rounding.
  auto consider = [&](const std::vector<std::size_t>& est) {
    if (!admissible(est)) return;
    ++choice.evaluated;
    const double v = value(est);
    if (gauge_criterion_less(v, est, best, choice.estimated, options.tie_tolerance)) {
      best = v;
      choice.estimated = est;
    }
  };

  // Number of r-subsets of the eligible columns, capped.
  double subsets = r <= eligible.size() ? 1.0 : 0.0;
  for (std::size_t k = 0; k < r && r <= eligible.size(); ++k)
    subsets = subsets * static_cast<double>(eligible.size() - k) / static_cast<double>(k + 1);
  if (subsets > 0.0 && subsets <= static_cast<double>(options.max_subsets)) {
    // Every set weighed, then the least criterion; ties (within the tolerance of the least) go
    // to the lexicographically first set, whatever order they were computed in.
    std::vector<std::pair<double, std::vector<std::size_t>>> weighed = {{best, choice.estimated}};
    std::vector<std::size_t> pick(r);
    for (std::size_t k = 0; k < r; ++k) pick[k] = k;
    while (true) {
      std::vector<std::size_t> est(r);
      for (std::size_t k = 0; k < r; ++k) est[k] = eligible[pick[k]];
      if (admissible(est)) {
        ++choice.evaluated;
        weighed.emplace_back(value(est), est);
      }
      // Next combination in lexicographic order.
      std::size_t k = r;
      while (k > 0 && pick[k - 1] == eligible.size() - r + k - 1) --k;
      if (k == 0) break;
      ++pick[k - 1];
      for (std::size_t m = k; m < r; ++m) pick[m] = pick[m - 1] + 1;
    }
    double least = std::numeric_limits<double>::infinity();
    for (const auto& w : weighed)
      if (std::isfinite(w.first)) least = std::min(least, w.first);
    const std::vector<std::size_t>* winner = nullptr;
    for (const auto& w : weighed)
      if (std::isfinite(w.first) && w.first - least <= options.tie_tolerance * std::abs(least) &&
          (winner == nullptr || w.second < *winner)) {
        winner = &w.second;
        best = w.first;
      }
    if (winner != nullptr) choice.estimated = *winner;
  } else {
    // Exchanges from the given set: the best single swap while it lowers the criterion (capped:
    // a tie rule on rounded values could otherwise cycle).
    bool improved = true;
    for (int round = 0; improved && round < 1000; ++round) {
      improved = false;
      const std::vector<std::size_t> current = choice.estimated;
      for (std::size_t k = 0; k < current.size(); ++k)
        for (std::size_t j : eligible) {
          if (std::find(current.begin(), current.end(), j) != current.end()) continue;
          std::vector<std::size_t> est = current;
          est[k] = j;
          std::sort(est.begin(), est.end());
          const std::vector<std::size_t> before = choice.estimated;
          consider(est);
          improved = improved || choice.estimated != before;
        }
    }
  }
  choice.expected_error = best;
  choice.bias = gauge_expected_error(problem, sigma, choice.estimated, /*bias_only=*/true);
  std::vector<std::size_t> sorted_initial = initial;
  std::sort(sorted_initial.begin(), sorted_initial.end());
  choice.changed = choice.estimated != sorted_initial;
  for (std::size_t j : eligible)
    if (!std::binary_search(choice.estimated.begin(), choice.estimated.end(), j))
      choice.held.push_back(j);
  return choice;
}

}  // namespace robocal::calib
