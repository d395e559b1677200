#include "robocal/calib/measurement_advice.hpp"

#include "robocal/calib/identifiability.hpp"

#include <fmt/core.h>

#include <algorithm>

namespace robocal::calib {

namespace {

// One candidate measurement and its whitened Jacobian rows (candidate columns only).
struct Candidate {
  SuggestedMeasurement what;
  Eigen::MatrixXd rows;
};

Eigen::MatrixXd columns_of(const Eigen::MatrixXd& J, const std::vector<std::size_t>& cols) {
  Eigen::MatrixXd out(J.rows(), static_cast<Eigen::Index>(cols.size()));
  for (std::size_t k = 0; k < cols.size(); ++k)
    out.col(static_cast<Eigen::Index>(k)) = J.col(static_cast<Eigen::Index>(cols[k]));
  return out;
}

Eigen::MatrixXd stacked(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  Eigen::MatrixXd out(a.rows() + b.rows(), std::max(a.cols(), b.cols()));
  if (a.rows() > 0) out.topRows(a.rows()) = a;
  if (b.rows() > 0) out.bottomRows(b.rows()) = b;
  return out;
}

// Rank and weakest separated singular value of the candidate columns of J (the identifiability
// analysis' own scaling and tolerance).
std::pair<std::size_t, double> strength(const Eigen::MatrixXd& J,
                                        const std::vector<std::string>& names) {
  if (J.rows() == 0) return {0, 0.0};
  const auto report = analyze_identifiability(J, names);
  const double weakest =
      report.rank > 0 && static_cast<Eigen::Index>(report.rank) <= report.singular_values.size()
          ? report.singular_values(static_cast<Eigen::Index>(report.rank) - 1)
          : 0.0;
  return {report.rank, weakest};
}

SuggestedMeasurement suggestion(const std::string& kind, const Eigen::VectorXd& actuators) {
  SuggestedMeasurement s;
  s.kind = kind;
  s.actuators = actuators;
  return s;
}

std::string where(const Eigen::Vector3d& p) {
  return fmt::format("({:.1f}, {:.1f}, {:.1f}) mm", 1e3 * p.x(), 1e3 * p.y(), 1e3 * p.z());
}

}  // namespace

MeasurementAdvice advise_measurements(const FramePredictor& model, const Eigen::VectorXd& params,
                                      const Measurements& current,
                                      const std::vector<std::size_t>& candidates,
                                      const std::vector<Eigen::VectorXd>& height_pool,
                                      const std::vector<Eigen::VectorXd>& pool,
                                      const AdviceOptions& options) {
  std::vector<std::size_t> cols = candidates;
  if (cols.empty())
    for (std::size_t i = 0; i < model.parameter_count(); ++i) cols.push_back(i);
  std::vector<std::string> names;
  const auto all_names = model.parameter_names();
  for (std::size_t i : cols) names.push_back(all_names[i]);

  MeasurementAdvice advice;
  Eigen::MatrixXd J(0, static_cast<Eigen::Index>(cols.size()));
  std::string why;
  Eigen::MatrixXd full;
  if (!current.poses.empty() && identification_jacobian(model, params, current, full, why))
    J = columns_of(full, cols);

  // The candidates and their rows.
  std::vector<Candidate> pool_rows;
  auto add = [&](Measurements m, SuggestedMeasurement what) {
    Eigen::MatrixXd rows;
    if (!identification_jacobian(model, params, m, rows, why)) return;
    FramePrediction a;
    if (!model.predict(params, what.actuators, -1, false, a, why)) return;
    what.position = a.pose.translation();
    if (what.actuators_b.size() > 0) {
      FramePrediction b;
      if (!model.predict(params, what.actuators_b, -1, false, b, why)) return;
      what.position_b = b.pose.translation();
    }
    pool_rows.push_back({std::move(what), columns_of(rows, cols)});
  };
  for (const auto& q : height_pool) {
    ProbeHeightObservation h;
    h.sigma = options.height_sigma;
    Measurements m;
    m.poses.push_back({"advice", q, {h}});
    add(m, suggestion("probe height", q));
  }
  if (options.points)
    for (const auto& q : pool) {
      Measurements m;
      m.poses.push_back(
          {"advice",
           q,
           {PointObservation::with_sigma(Eigen::Vector3d::Zero(), options.point_sigma)}});
      add(m, suggestion("3-D point", q));
    }
  if (options.distances) {
    const std::size_t n = std::min(options.distance_positions, pool.size());
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j) {
        Measurements m;
        m.poses.push_back({"a", pool[i], {}});
        m.poses.push_back({"b", pool[j], {}});
        DistanceMeasurement d;
        d.first = "a";
        d.second = "b";
        d.observation.sigma = options.distance_sigma;
        m.distances.push_back(d);
        SuggestedMeasurement what = suggestion("distance", pool[i]);
        what.actuators_b = pool[j];
        add(m, what);
      }
  }

  auto [rank, weakest] = strength(J, names);
  advice.rank_before = rank;
  {
    Eigen::MatrixXd everything = J;
    for (const auto& c : pool_rows) everything = stacked(everything, c.rows);
    advice.rank_reachable = strength(everything, names).first;
  }
  // Greedy: the candidate that raises the rank most, then the weakest direction most.
  std::vector<bool> used(pool_rows.size(), false);
  auto wanted = [&] {
    return rank < advice.rank_reachable ||
           static_cast<std::size_t>(J.rows()) < advice.rank_reachable + options.redundancy;
  };
  while (wanted() && advice.suggestions.size() < options.max_suggestions) {
    std::size_t best = pool_rows.size();
    std::pair<std::size_t, double> best_strength{rank, weakest};
    for (std::size_t c = 0; c < pool_rows.size(); ++c) {
      if (used[c]) continue;
      const auto s = strength(stacked(J, pool_rows[c].rows), names);
      if (s.first > best_strength.first ||
          (s.first == best_strength.first && s.second > best_strength.second)) {
        best = c;
        best_strength = s;
      }
    }
    if (best == pool_rows.size()) {  // nothing raises the rank or the weakest direction
      if (rank < advice.rank_reachable) break;
      // Redundancy only: the candidate that best keeps the weakest direction.
      double keep = -1.0;
      for (std::size_t c = 0; c < pool_rows.size(); ++c)
        if (!used[c]) {
          const auto s = strength(stacked(J, pool_rows[c].rows), names);
          if (s.second > keep) {
            keep = s.second;
            best = c;
            best_strength = s;
          }
        }
      if (best == pool_rows.size()) break;
    }
    used[best] = true;
    J = stacked(J, pool_rows[best].rows);
    rank = best_strength.first;
    weakest = best_strength.second;
    pool_rows[best].what.rank_after = rank;
    advice.suggestions.push_back(pool_rows[best].what);
  }
  advice.rank_after = rank;
  if (advice.suggestions.empty()) return advice;
  advice.text = fmt::format(
      "To separate {} more of the {} parameters (identifiable now: {}) with equations to spare, "
      "measure next:\n",
      advice.rank_after - advice.rank_before, cols.size(), advice.rank_before);
  for (const auto& s : advice.suggestions) {
    if (s.kind == "distance")
      advice.text += fmt::format("  - the distance between the positions at {} and {}\n",
                                 where(s.position), where(s.position_b));
    else
      advice.text += fmt::format("  - a {} at {}\n", s.kind, where(s.position));
  }
  if (advice.rank_after < cols.size())
    advice.text +=
        fmt::format("  ({} parameters stay confounded with every measurement of these kinds.)\n",
                    cols.size() - advice.rank_after);
  return advice;
}

}  // namespace robocal::calib
