#include "robocal/calib/probe_design.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace robocal::calib {

namespace {

// trace(M⁻¹ A) for symmetric positive definite M; +inf otherwise.
double trace_of_inverse_times(const Eigen::MatrixXd& M, const Eigen::MatrixXd& A) {
  const Eigen::LLT<Eigen::MatrixXd> llt(M);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const double t = llt.solve(A).trace();
  return std::isfinite(t) && t >= 0.0 ? t : std::numeric_limits<double>::infinity();
}

}  // namespace

double average_prediction_variance(const Eigen::MatrixXd& information,
                                   const Eigen::MatrixXd& targets, double ridge) {
  if (targets.rows() == 0) return 0.0;
  const auto p = information.rows();
  const Eigen::MatrixXd A = targets.transpose() * targets / static_cast<double>(targets.rows());
  return trace_of_inverse_times(information + ridge * Eigen::MatrixXd::Identity(p, p), A);
}

Eigen::MatrixXd target_second_moment(const Eigen::MatrixXd& targets) {
  return targets.transpose() * targets / static_cast<double>(targets.rows());
}

HeldPredictionError prediction_error_parts_with_held(const Eigen::MatrixXd& information,
                                                     const Eigen::MatrixXd& target_moment,
                                                     const std::vector<std::size_t>& held,
                                                     const Eigen::VectorXd& held_sigma) {
  const Eigen::MatrixXd& A = target_moment;
  const Eigen::Index p = information.rows();
  std::vector<bool> is_held(static_cast<std::size_t>(p), false);
  for (std::size_t i : held) is_held.at(i) = true;
  std::vector<Eigen::Index> S;
  std::vector<Eigen::Index> H;
  for (Eigen::Index i = 0; i < p; ++i) (is_held[static_cast<std::size_t>(i)] ? H : S).push_back(i);
  const auto ns = static_cast<Eigen::Index>(S.size());
  const auto nh = static_cast<Eigen::Index>(H.size());
  auto block = [](const Eigen::MatrixXd& X, const std::vector<Eigen::Index>& r,
                  const std::vector<Eigen::Index>& c) {
    Eigen::MatrixXd out(static_cast<Eigen::Index>(r.size()), static_cast<Eigen::Index>(c.size()));
    for (std::size_t i = 0; i < r.size(); ++i)
      for (std::size_t j = 0; j < c.size(); ++j)
        out(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = X(r[i], c[j]);
    return out;
  };
  HeldPredictionError parts;
  Eigen::MatrixXd K(ns, nh);
  if (ns > 0) {
    const Eigen::LLT<Eigen::MatrixXd> llt(block(information, S, S));
    if (llt.info() != Eigen::Success) return {std::numeric_limits<double>::infinity(), 0.0};
    parts.variance = llt.solve(block(A, S, S)).trace();
    // With no held column the right-hand side is empty: solved as one zero column and dropped
    // (Eigen's triangular solve of an empty matrix binds a reference to its first element,
    // undefined behaviour the sanitizers stop on).
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(ns, std::max<Eigen::Index>(nh, 1));
    if (nh > 0) rhs = block(information, S, H);
    K = llt.solve(rhs).leftCols(nh);
  }
  if (nh > 0) {
    // Error per unit held deviation: g_S K − g_H, i.e. E = [K; −I] over (S, H).
    Eigen::MatrixXd E(p, nh);
    std::vector<Eigen::Index> order = S;
    order.insert(order.end(), H.begin(), H.end());
    E.topRows(ns) = K;
    E.bottomRows(nh) = -Eigen::MatrixXd::Identity(nh, nh);
    Eigen::VectorXd d(nh);
    for (Eigen::Index k = 0; k < nh; ++k) d(k) = held_sigma(H[static_cast<std::size_t>(k)]);
    const Eigen::MatrixXd ED = E * d.asDiagonal();
    parts.bias = (ED.transpose() * block(A, order, order) * ED).trace();
  }
  return parts;
}

double average_prediction_error_with_held(const Eigen::MatrixXd& information,
                                          const Eigen::MatrixXd& targets,
                                          const std::vector<std::size_t>& held,
                                          const Eigen::VectorXd& held_sigma) {
  if (targets.rows() == 0) return 0.0;
  const HeldPredictionError parts = prediction_error_parts_with_held(
      information, target_second_moment(targets), held, held_sigma);
  const double total = parts.variance + parts.bias;
  return std::isfinite(total) ? total : std::numeric_limits<double>::infinity();
}

ExactDesign i_optimal_design(const std::vector<Eigen::MatrixXd>& candidate_rows,
                             const Eigen::MatrixXd& targets, const Eigen::MatrixXd& information0,
                             std::size_t count, const DesignOptions& options) {
  const Eigen::Index p = targets.cols();
  Eigen::MatrixXd M0 = information0.size() > 0 ? information0 : Eigen::MatrixXd::Zero(p, p);
  if (M0.rows() != p || M0.cols() != p)
    throw std::invalid_argument(
        "i_optimal_design: information0 must be p x p (p = target columns)");
  std::vector<Eigen::MatrixXd> info;  // FᵀF per candidate
  info.reserve(candidate_rows.size());
  Eigen::MatrixXd total = Eigen::MatrixXd::Zero(p, p);
  for (const auto& F : candidate_rows) {
    if (F.cols() != p)
      throw std::invalid_argument("i_optimal_design: candidate rows must have p columns");
    info.emplace_back(F.transpose() * F);
    total += info.back();
  }
  double scale = 0.0;
  for (Eigen::Index i = 0; i < p; ++i) scale = std::max({scale, total(i, i), M0(i, i)});
  const Eigen::MatrixXd ridge =
      options.ridge * (scale > 0.0 ? scale : 1.0) * Eigen::MatrixXd::Identity(p, p);
  const Eigen::MatrixXd A =
      targets.rows() > 0
          ? Eigen::MatrixXd(targets.transpose() * targets / static_cast<double>(targets.rows()))
          : Eigen::MatrixXd::Zero(p, p);
  if (options.held && options.held_sigma.size() != p)
    throw std::invalid_argument("i_optimal_design: held_sigma must have one entry per parameter");
  std::vector<std::size_t> picked;  // the design being evaluated (for `held`)
  auto objective = [&](const Eigen::MatrixXd& M) {
    if (options.held) {
      Eigen::Index n = 0;
      for (std::size_t c : picked) n += candidate_rows[c].rows();
      Eigen::MatrixXd rows(n, p);
      n = 0;
      for (std::size_t c : picked) {
        rows.middleRows(n, candidate_rows[c].rows()) = candidate_rows[c];
        n += candidate_rows[c].rows();
      }
      return average_prediction_error_with_held(M, targets, options.held(rows), options.held_sigma);
    }
    return trace_of_inverse_times(M + ridge, A);
  };

  // The objective of `base` + each candidate's rows (those `skip` rejects get +inf). Without
  // `held`, by the Woodbury identity from one factorisation of `base`: with B = (base + ridge)⁻¹,
  // adding the rows F lowers trace(B A) by trace((I + F B Fᵀ)⁻¹ F B A B Fᵀ).
  auto values_with = [&](const Eigen::MatrixXd& base, const std::function<bool(std::size_t)>& skip,
                         const std::function<void(std::size_t)>& set_picked) {
    std::vector<double> v(candidate_rows.size(), std::numeric_limits<double>::infinity());
    const Eigen::LLT<Eigen::MatrixXd> llt(base + ridge);
    const bool fast = !options.held && llt.info() == Eigen::Success;
    Eigen::MatrixXd B;
    Eigen::MatrixXd C;
    double t0 = 0.0;
    if (fast) {
      B = llt.solve(Eigen::MatrixXd::Identity(p, p));
      C = B * A * B;
      t0 = (B * A).trace();
    }
    for (std::size_t c = 0; c < candidate_rows.size(); ++c) {
      if (skip(c)) continue;
      if (!fast) {
        set_picked(c);
        v[c] = objective(base + info[c]);
        continue;
      }
      const Eigen::MatrixXd& F = candidate_rows[c];
      Eigen::MatrixXd S = F * B * F.transpose();
      S.diagonal().array() += 1.0;
      const double fall = S.llt().solve(F * C * F.transpose()).trace();
      v[c] = t0 - fall;
    }
    return v;
  };

  ExactDesign design;
  if (!options.allow_repeats) count = std::min(count, candidate_rows.size());
  std::vector<int> times(candidate_rows.size(), 0);
  Eigen::MatrixXd M = M0;
  // Greedy: the candidate that lowers the average most (ties: the first).
  while (design.chosen.size() < count) {
    std::size_t best = candidate_rows.size();
    double best_value = std::numeric_limits<double>::infinity();
    const auto values = values_with(
        M, [&](std::size_t c) { return !options.allow_repeats && times[c] > 0; },
        [&](std::size_t c) {
          picked = design.chosen;
          picked.push_back(c);
        });
    for (std::size_t c = 0; c < candidate_rows.size(); ++c) {
      if (!options.allow_repeats && times[c] > 0) continue;
      if (values[c] < best_value || best == candidate_rows.size()) {
        best = c;
        best_value = values[c];
      }
    }
    if (best == candidate_rows.size()) break;
    design.chosen.push_back(best);
    ++times[best];
    M += info[best];
  }
  picked = design.chosen;
  double value = objective(M);
  design.greedy_average_variance = value;
  // Exchange sweeps: each chosen point in turn is swapped for the candidate that lowers the
  // average most (by more than rounding), until a sweep changes nothing.
  for (int pass = 0; pass < options.max_exchange_passes; ++pass) {
    bool changed = false;
    for (std::size_t k = 0; k < design.chosen.size(); ++k) {
      const std::size_t out = design.chosen[k];
      const Eigen::MatrixXd without = M - info[out];
      double best_value = value;
      std::size_t in_c = candidate_rows.size();
      auto skip = [&](std::size_t c) {
        return c == out || (!options.allow_repeats && times[c] > 0);
      };
      const auto values = values_with(without, skip, [&](std::size_t c) {
        picked = design.chosen;
        picked[k] = c;
      });
      for (std::size_t c = 0; c < candidate_rows.size(); ++c) {
        if (skip(c)) continue;
        if (values[c] < best_value * (1.0 - 1e-12)) {
          best_value = values[c];
          in_c = c;
        }
      }
      if (in_c == candidate_rows.size()) continue;
      --times[out];
      design.chosen[k] = in_c;
      ++times[in_c];
      ++design.exchanges;
      changed = true;
      M = M0;  // summed afresh: no drift from repeated add and subtract
      for (std::size_t c : design.chosen) M += info[c];
      picked = design.chosen;
      value = objective(M);
    }
    if (!changed) break;
  }
  design.average_variance = value;
  return design;
}

}  // namespace robocal::calib
