#include "robocal/calib/identifiability.hpp"

#include <fmt/core.h>
#include <Eigen/Dense>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace robocal::calib {

bool IdentifiabilityReport::is_identifiable(std::size_t parameter) const {
  return std::binary_search(identifiable.begin(), identifiable.end(), parameter);
}

namespace {

// The triangular factor of a QR of the scaled Jacobian has the same column geometry (inner
// products, singular values) as the Jacobian itself but at most p rows: every later step works
// on it, so the analysis costs O(rows·p²) once and then O(p³).
Eigen::MatrixXd compress_rows(const Eigen::MatrixXd& scaled) {
  if (scaled.rows() <= scaled.cols()) return scaled;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(scaled);
  return qr.matrixQR().topRows(scaled.cols()).triangularView<Eigen::Upper>();
}

// Two remaining norms within this relative distance count as equal and the lower parameter index
// wins. Rounding-level differences of the input (1e-16; a YAML round trip of the measured poses)
// must not change the base set, real differences in independence (>= 1e-6) still decide.
constexpr double kTieTolerance = 1e-6;

// stable_tie_break: greedy base set = column-pivoted Householder QR of R with our own pivot rule:
// preference classes in ascending order; within a class the open column with the largest part
// outside the span of the kept columns (remaining norm) is kept next, ties within kTieTolerance
// broken by index. When the largest remaining norm of a class is <= rank_tolerance, the class's
// open columns are redundant. Eigen's pivot order is not used because among exactly confounded
// columns (equal remaining norms) it follows the rounding of the input. Cost O(rank * rows * p).
std::vector<bool> select_base_set(const Eigen::MatrixXd& R, const std::vector<bool>& has_effect,
                                  const std::vector<int>& preference, double rank_tolerance) {
  const auto p = static_cast<std::size_t>(R.cols());
  const Eigen::Index rows = R.rows();
  auto class_of = [&](std::size_t j) { return preference.empty() ? 0 : preference[j]; };
  std::vector<int> classes;
  for (std::size_t j = 0; j < p; ++j) classes.push_back(class_of(j));
  std::sort(classes.begin(), classes.end());
  classes.erase(std::unique(classes.begin(), classes.end()), classes.end());

  Eigen::MatrixXd W = R;  // rows [0, step) hold the kept columns' coordinates, the rest remains
  Eigen::VectorXd workspace(R.cols());
  std::vector<bool> kept(p, false);
  std::vector<bool> open = has_effect;
  Eigen::Index step = 0;
  std::vector<double> remaining(p, 0.0);
  for (const int cls : classes) {
    while (true) {
      double largest = 0.0;
      bool any = false;
      for (std::size_t j = 0; j < p; ++j) {
        if (!open[j] || class_of(j) != cls) continue;
        remaining[j] =
            step < rows ? W.col(static_cast<Eigen::Index>(j)).tail(rows - step).norm() : 0.0;
        largest = std::max(largest, remaining[j]);
        any = true;
      }
      if (!any) break;
      if (largest <= rank_tolerance) {
        for (std::size_t j = 0; j < p; ++j)
          if (class_of(j) == cls) open[j] = false;
        break;
      }
      std::size_t pick = p;
      for (std::size_t j = 0; j < p && pick == p; ++j)
        if (open[j] && class_of(j) == cls && remaining[j] >= (1.0 - kTieTolerance) * largest)
          pick = j;
      kept[pick] = true;
      open[pick] = false;
      // Reflect rows [step, rows) so the picked column has no part left there: the tails of the
      // other columns are then exactly their parts outside the span of the kept columns.
      const Eigen::Index n = rows - step;
      Eigen::VectorXd essential(n - 1);
      double tau = 0.0;
      double beta = 0.0;
      W.col(static_cast<Eigen::Index>(pick)).tail(n).makeHouseholder(essential, tau, beta);
      W.bottomRows(n).applyHouseholderOnTheLeft(essential, tau, workspace.data());
      ++step;
    }
  }
  return kept;
}

// The original rule (default): visiting order = preference, then the pivot order of Eigen's
// column-pivoted QR of R; a column is kept when its part outside the span of the columns kept
// before it exceeds rank_tolerance (modified Gram-Schmidt, applied twice for orthogonality).
// Among exactly confounded columns of equal preference the pivot order follows the rounding of
// the input, see IdentifiabilityOptions::stable_tie_break.
std::vector<bool> select_base_set_qr_order(const Eigen::MatrixXd& R,
                                           const std::vector<bool>& has_effect,
                                           const std::vector<int>& preference,
                                           double rank_tolerance) {
  const auto p = static_cast<std::size_t>(R.cols());
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> pivoted(R);
  std::vector<std::size_t> pivot_rank(p);
  for (Eigen::Index k = 0; k < pivoted.colsPermutation().indices().size(); ++k)
    pivot_rank[static_cast<std::size_t>(pivoted.colsPermutation().indices()(k))] =
        static_cast<std::size_t>(k);
  std::vector<std::size_t> order(p);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const int pa = preference.empty() ? 0 : preference[a];
    const int pb = preference.empty() ? 0 : preference[b];
    if (pa != pb) return pa < pb;
    return pivot_rank[a] < pivot_rank[b];
  });
  std::vector<Eigen::VectorXd> basis;
  std::vector<bool> kept(p, false);
  for (std::size_t j : order) {
    if (!has_effect[j]) continue;
    Eigen::VectorXd r = R.col(static_cast<Eigen::Index>(j));
    for (int pass = 0; pass < 2; ++pass)
      for (const auto& q : basis) r -= q.dot(r) * q;
    const double outside = r.norm();
    if (outside > rank_tolerance) {
      basis.emplace_back(r / outside);
      kept[j] = true;
    }
  }
  return kept;
}

std::string join_combination(const std::vector<std::string>& names,
                             const std::vector<std::size_t>& partners,
                             const std::vector<double>& coefficients) {
  std::string text;
  const std::size_t shown = std::min<std::size_t>(partners.size(), 6);
  for (std::size_t i = 0; i < shown; ++i) {
    if (i > 0) text += i + 1 == shown && shown == partners.size() ? " and " : ", ";
    text += fmt::format("{:+.3g} x {}", coefficients[i], names[partners[i]]);
  }
  if (shown < partners.size()) text += fmt::format(" and {} more", partners.size() - shown);
  return text;
}

// The redundant parameters with an effect, each expressed through the base set (report.redundant
// and report.identifiable filled; report.rank > 0).
void add_redundancies(const Eigen::MatrixXd& R, const Eigen::MatrixXd& R_base,
                      const std::vector<bool>& has_effect, const std::vector<std::string>& names,
                      const IdentifiabilityOptions& options, IdentifiabilityReport& report) {
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> base_solver(R_base);
  for (std::size_t f : report.redundant) {
    if (!has_effect[f]) continue;
    const Eigen::VectorXd target = R.col(static_cast<Eigen::Index>(f));
    const Eigen::VectorXd c = base_solver.solve(target);
    Redundancy red;
    red.parameter = f;
    red.residual = (R_base * c - target).norm();
    std::vector<std::size_t> idx(report.rank);
    std::iota(idx.begin(), idx.end(), std::size_t{0});
    std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) {
      return std::abs(c(static_cast<Eigen::Index>(a))) > std::abs(c(static_cast<Eigen::Index>(b)));
    });
    for (std::size_t k : idx) {
      const double ck = c(static_cast<Eigen::Index>(k));
      if (std::abs(ck) < options.involvement_threshold) break;
      const std::size_t s = report.identifiable[k];
      red.partners.push_back(s);
      red.coefficients.push_back(ck * report.column_norms(static_cast<Eigen::Index>(f)) /
                                 report.column_norms(static_cast<Eigen::Index>(s)));
    }
    if (red.partners.empty()) {
      red.explanation = fmt::format(
          "{} is a combination of many small contributions of other parameters with this "
          "data; it is held at its nominal value",
          names[f]);
    } else {
      red.explanation = fmt::format(
          "{} moves the measurements the same way as {} with this data; they cannot be told "
          "apart, so {} is held at its nominal value and only their combination is identified",
          names[f], join_combination(names, red.partners, red.coefficients), names[f]);
    }
    report.redundancies.push_back(std::move(red));
  }
}

// The weak directions among the identifiable parameters and the condition number (report.rank
// > 0).
void add_weak_directions(const Eigen::MatrixXd& R_base, const std::vector<std::string>& names,
                         const IdentifiabilityOptions& options, IdentifiabilityReport& report) {
  const std::size_t p = names.size();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(R_base, Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  const Eigen::Index last = std::min<Eigen::Index>(s.size(), R_base.cols()) - 1;
  report.condition_number = s(last) > 0.0 ? s(0) / s(last) : INFINITY;
  for (Eigen::Index i = 0; i <= last; ++i) {
    const double rel = s(i) / s(0);
    if (rel >= options.ill_conditioning_ratio) continue;
    IllConditionedDirection dir;
    dir.relative_singular_value = rel;
    const Eigen::VectorXd v = svd.matrixV().col(i);
    dir.direction.assign(p, 0.0);
    for (std::size_t k = 0; k < report.rank; ++k)
      dir.direction[report.identifiable[k]] = v(static_cast<Eigen::Index>(k));
    std::vector<std::size_t> idx(report.rank);
    std::iota(idx.begin(), idx.end(), std::size_t{0});
    std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) {
      return std::abs(v(static_cast<Eigen::Index>(a))) > std::abs(v(static_cast<Eigen::Index>(b)));
    });
    if (idx.empty()) continue;  // cannot happen (rank > 0); tells GCC's -Wnull-dereference
    dir.first = report.identifiable[idx[0]];
    dir.second = report.identifiable[idx.size() > 1 ? idx[1] : idx[0]];
    std::string others;
    for (std::size_t k = 2; k < idx.size(); ++k) {
      const double vk = v(static_cast<Eigen::Index>(idx[k]));
      if (std::abs(vk) < 0.2) break;
      others += fmt::format(", {} ({:+.2f})", names[report.identifiable[idx[k]]], vk);
    }
    dir.explanation = fmt::format(
        "{} and {} are barely separated by this data (relative singular value {:.2g}, "
        "condition {:.3g}): they move the measurements almost the same way, so their estimates "
        "are strongly correlated and sensitive to noise; add poses that separate them or fix "
        "one (weak direction: {} ({:+.2f}), {} ({:+.2f}){})",
        names[dir.first], names[dir.second], rel, 1.0 / rel, names[dir.first],
        v(static_cast<Eigen::Index>(idx[0])), names[dir.second],
        v(static_cast<Eigen::Index>(idx.size() > 1 ? idx[1] : idx[0])), others);
    report.ill_conditioned.push_back(std::move(dir));
  }
}

}  // namespace

IdentifiabilityReport analyze_identifiability(const Eigen::MatrixXd& J,
                                              const std::vector<std::string>& names,
                                              const IdentifiabilityOptions& options,
                                              const std::vector<int>& preference) {
  const auto p = static_cast<std::size_t>(J.cols());
  if (names.size() != p)
    throw std::invalid_argument(fmt::format(
        "identifiability: {} parameter names for a Jacobian with {} columns", names.size(), p));
  if (!preference.empty() && preference.size() != p)
    throw std::invalid_argument("identifiability: preference must have one entry per parameter");
  if (!J.allFinite())
    throw std::invalid_argument("identifiability: the Jacobian contains NaN or infinite values");

  IdentifiabilityReport report;
  report.names = names;
  report.rows = static_cast<std::size_t>(J.rows());
  report.underdetermined = report.rows < p;
  report.column_norms = J.colwise().norm().transpose();
  if (p == 0) return report;

  const double largest = report.column_norms.maxCoeff();
  Eigen::MatrixXd scaled = J;
  std::vector<bool> has_effect(p, false);
  for (std::size_t j = 0; j < p; ++j) {
    const double n = report.column_norms(static_cast<Eigen::Index>(j));
    has_effect[j] = largest > 0.0 && n > options.no_effect_tolerance * largest;
    if (has_effect[j])
      scaled.col(static_cast<Eigen::Index>(j)) /= n;
    else
      scaled.col(static_cast<Eigen::Index>(j)).setZero();
  }
  const Eigen::MatrixXd R = compress_rows(scaled);
  report.singular_values = Eigen::JacobiSVD<Eigen::MatrixXd>(R).singularValues();

  const std::vector<bool> kept =
      options.stable_tie_break
          ? select_base_set(R, has_effect, preference, options.rank_tolerance)
          : select_base_set_qr_order(R, has_effect, preference, options.rank_tolerance);
  for (std::size_t j = 0; j < p; ++j) {
    if (kept[j])
      report.identifiable.push_back(j);
    else
      report.redundant.push_back(j);
    if (!has_effect[j]) report.no_effect.push_back(j);
  }
  report.rank = report.identifiable.size();

  Eigen::MatrixXd R_base(R.rows(), static_cast<Eigen::Index>(report.rank));
  for (std::size_t k = 0; k < report.rank; ++k)
    R_base.col(static_cast<Eigen::Index>(k)) =
        R.col(static_cast<Eigen::Index>(report.identifiable[k]));

  if (report.rank > 0) {
    add_redundancies(R, R_base, has_effect, names, options, report);
    add_weak_directions(R_base, names, options, report);
  }

  report.messages.push_back(fmt::format(
      "{} candidate parameters, {} measurement equations: {} identifiable, {} held at nominal "
      "(rank tolerance {:.1g} on the column-scaled Jacobian), condition number {:.3g}",
      p, report.rows, report.rank, report.redundant.size(), options.rank_tolerance,
      report.condition_number));
  if (report.underdetermined)
    report.messages.push_back(fmt::format(
        "underdetermined: only {} measurement equations for {} candidate parameters; add poses",
        report.rows, p));
  if (!report.no_effect.empty()) {
    std::string list;
    for (std::size_t j : report.no_effect) list += (list.empty() ? "" : ", ") + names[j];
    report.messages.push_back(fmt::format(
        "{} parameter(s) have no effect on any measurement with this data and are held at "
        "nominal: {}",
        report.no_effect.size(), list));
  }
  for (const auto& red : report.redundancies) report.messages.push_back(red.explanation);
  for (const auto& dir : report.ill_conditioned) report.messages.push_back(dir.explanation);
  return report;
}

}  // namespace robocal::calib
