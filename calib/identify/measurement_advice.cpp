#include "robocal/calib/measurement_advice.hpp"

#include "robocal/calib/identifiability.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/probe_design.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <random>

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

// Rows (candidate columns) of the predicted quantity at `readings`: the bed height (unit σ) when
// `heights`, else the three position coordinates. Readings the model cannot predict are skipped.
Eigen::MatrixXd prediction_rows(const FramePredictor& model, const Eigen::VectorXd& params,
                                const std::vector<std::size_t>& cols,
                                const std::vector<Eigen::VectorXd>& readings, bool heights) {
  Eigen::MatrixXd out(0, static_cast<Eigen::Index>(cols.size()));
  for (const auto& q : readings) {
    Measurements m;
    if (heights) {
      ProbeHeightObservation h;
      h.sigma = 1.0;
      m.poses.push_back({"area", q, {h}});
    } else {
      m.poses.push_back({"area", q, {PointObservation::with_sigma(Eigen::Vector3d::Zero(), 1.0)}});
    }
    Eigen::MatrixXd rows;
    std::string why;
    if (identification_jacobian(model, params, m, rows, why))
      out = stacked(out, columns_of(rows, cols));
  }
  return out;
}

// The held-parameter criterion runs identify's analysis for every design it weighs: affordable
// for a printer's parameter set (9: ~0.5 s for the identify command's advice), not for every
// parameter of a robot file (49 on the linear delta: 20 s); those get the variance criterion.
constexpr std::size_t kHeldModelMaxParameters = 16;

// As many suggestions as the rank rule chose, chosen again I-optimally for the predictions over
// the working area (probe_design.hpp); kept unless they separate fewer parameters.
void redesign(const FramePredictor& model, const Eigen::VectorXd& params,
              const std::vector<std::size_t>& cols, const std::vector<std::string>& names,
              const Eigen::MatrixXd& J_now, const std::vector<Candidate>& pool_rows,
              const std::vector<Eigen::VectorXd>& height_pool,
              const std::vector<Eigen::VectorXd>& pool, const AdviceOptions& options,
              MeasurementAdvice& advice) {
  const bool heights = !height_pool.empty();
  const auto& area = !options.working_area.empty() ? options.working_area
                     : heights                     ? height_pool
                                                   : pool;
  const Eigen::MatrixXd targets = prediction_rows(model, params, cols, area, heights);
  if (targets.rows() == 0) return;
  const auto n = static_cast<Eigen::Index>(cols.size());
  Eigen::MatrixXd M0 = Eigen::MatrixXd::Zero(n, n);
  if (J_now.rows() > 0) M0 = J_now.transpose() * J_now;
  Eigen::VectorXd sigma = Eigen::VectorXd::Zero(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    const std::size_t i = cols[static_cast<std::size_t>(k)];
    if (i < options.prior_sigma.size()) sigma(k) = options.prior_sigma[i];
  }
  const bool priors = n > 0 && sigma.minCoeff() > 0.0;
  std::vector<Eigen::MatrixXd> rows;
  rows.reserve(pool_rows.size());
  std::size_t design_rows = static_cast<std::size_t>(J_now.rows());
  for (const auto& c : pool_rows) rows.push_back(c.rows);
  for (const auto& s : advice.suggestions) design_rows += s.kind == "3-D point" ? 3 : 1;
  DesignOptions design_options;
  if (priors && options.map_estimator) {
    for (Eigen::Index k = 0; k < n; ++k) M0(k, k) += 1.0 / (sigma(k) * sigma(k));
  } else if (priors && cols.size() <= kHeldModelMaxParameters) {
    // What identify will hold at nominal with these rows: its analysis, with the little-data
    // rule's stricter tolerance when the equations are fewer than the parameters.
    IdentifiabilityOptions analysis;
    if (design_rows < cols.size()) analysis.rank_tolerance = analysis.ill_conditioning_ratio;
    std::vector<int> preference;
    if (!options.preference.empty())
      for (std::size_t i : cols)
        preference.push_back(i < options.preference.size() ? options.preference[i] : 0);
    design_options.held = [names, analysis, preference, &J_now](const Eigen::MatrixXd& chosen) {
      return analyze_identifiability(stacked(J_now, chosen), names, analysis, preference).redundant;
    };
    design_options.held_sigma = sigma;
  }
  const auto design =
      i_optimal_design(rows, targets, M0, advice.suggestions.size(), design_options);
  if (design.chosen.size() != advice.suggestions.size()) return;
  std::vector<SuggestedMeasurement> chosen;
  Eigen::MatrixXd J = J_now;
  std::size_t rank = 0;
  for (std::size_t c : design.chosen) {
    J = stacked(J, pool_rows[c].rows);
    rank = strength(J, names).first;
    chosen.push_back(pool_rows[c].what);
    chosen.back().rank_after = rank;
  }
  if (rank < advice.rank_after) return;
  advice.suggestions = std::move(chosen);
  advice.rank_after = rank;
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
  names.reserve(cols.size());
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
  auto add = [&](const Measurements& m, SuggestedMeasurement what) {
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

  const Eigen::MatrixXd J_now = J;
  const auto start = strength(J, names);
  std::size_t rank = start.first;
  double weakest = start.second;
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
  if (options.design && !advice.suggestions.empty())
    redesign(model, params, cols, names, J_now, pool_rows, height_pool, pool, options, advice);
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

namespace {

// Where the measured frame is at each pose of `poses` (at `params`), skipping what cannot be
// predicted.
std::vector<Eigen::Vector3d> positions(const FramePredictor& model, const Eigen::VectorXd& params,
                                       const std::vector<const PoseMeasurement*>& poses) {
  std::vector<Eigen::Vector3d> out;
  for (const auto* p : poses) {
    FramePrediction f;
    std::string why;
    if (model.predict(params, p->actuators, -1, false, f, why))
      out.emplace_back(f.pose.translation());
  }
  return out;
}

// Readings that put the frame on a grid over the area of `around` (1.15 × its radius about its
// centroid, 7 × 7 steps) at its mean height.
std::vector<Eigen::VectorXd> grid_like(const MechanismPredictor& robot,
                                       const Eigen::VectorXd& robot_params,
                                       const std::vector<Eigen::Vector3d>& around) {
  std::vector<Eigen::VectorXd> out;
  if (around.empty()) return out;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : around) c += p;
  c /= static_cast<double>(around.size());
  double radius = 0.0;
  for (const auto& p : around) radius = std::max(radius, (p - c).head<2>().norm());
  radius = std::max(1.15 * radius, 1e-3);
  for (int i = -3; i <= 3; ++i)
    for (int j = -3; j <= 3; ++j) {
      const Eigen::Vector2d xy = c.head<2>() + radius / 3.0 * Eigen::Vector2d(i, j);
      if ((xy - c.head<2>()).norm() > radius + 1e-12) continue;
      TaskTarget t;
      t.pose.translation() = Eigen::Vector3d(xy.x(), xy.y(), c.z());
      const auto ik = solve_ik(robot.model(), robot_params, t);
      if (ik.ok()) out.push_back(ik.actuator_readings);
    }
  return out;
}

}  // namespace

MeasurementAdvice advise_like_the_data(const MechanismPredictor& robot, const FramePredictor& model,
                                       const Eigen::VectorXd& params, const Measurements& current,
                                       const std::vector<std::size_t>& candidates,
                                       AdviceOptions options) {
  const Eigen::VectorXd robot_params =
      params.head(static_cast<Eigen::Index>(robot.parameter_count()));
  std::vector<const PoseMeasurement*> probed;
  bool points = false;
  for (const auto& p : current.poses) {
    bool height = false;
    for (const auto& o : p.observations) {
      height = height || std::holds_alternative<ProbeHeightObservation>(o);
      points = points || std::holds_alternative<PointObservation>(o) ||
               std::holds_alternative<PoseObservation>(o);
    }
    if (height) probed.push_back(&p);
  }
  std::vector<const PoseMeasurement*> distance_poses;
  for (const auto& d : current.distances)
    for (const auto& p : current.poses)
      if (p.id == d.first || p.id == d.second) distance_poses.push_back(&p);
  const auto probed_at = positions(robot, robot_params, probed);
  const auto height_pool = grid_like(robot, robot_params, probed_at);
  // Distances like the user's, or, for a printer that only probed, on a part printed one layer
  // (5 mm) above the bed: a caliper is at hand where a probe is.
  auto distance_at = positions(robot, robot_params, distance_poses);
  if (distance_at.empty())
    for (const auto& p : probed_at) distance_at.emplace_back(p + Eigen::Vector3d(0.0, 0.0, 5e-3));
  std::vector<Eigen::VectorXd> pool = grid_like(robot, robot_params, distance_at);
  options.distances = !distance_at.empty();
  options.points = points;
  // The design weighs what stays held at nominal by the robot file's tolerances.
  if (options.prior_sigma.empty())
    for (const auto& prm : robot.model().parameters) options.prior_sigma.push_back(prm.sigma);
  if (options.preference.empty()) {
    // identify's base-set preference (what it holds); a wrapper's own parameters (the bed
    // plane) after the robot's, as BedPlanePredictor orders them.
    options.preference = solve_options_from_model(robot.model(), false).preference;
    const int last = options.preference.empty()
                         ? 0
                         : *std::max_element(options.preference.begin(), options.preference.end());
    options.preference.resize(model.parameter_count(), last + 1);
  }
  auto add_sampled = [&] {
    std::mt19937 rng(1);
    for (auto& q : sample_actuators(robot, {robot_params}, 40, rng)) pool.push_back(std::move(q));
  };
  if (points) add_sampled();
  auto advice = advise_measurements(model, params, current, candidates, height_pool, pool, options);
  if (advice.suggestions.empty() && !points) {
    // Nothing of the user's kinds helps: what 3-D points (a tracker, cameras) would add.
    options.points = true;
    add_sampled();
    advice = advise_measurements(model, params, current, candidates, height_pool, pool, options);
  }
  return advice;
}

}  // namespace robocal::calib
