// The solve of identify(): the problem assembled from the accepted poses, the estimated set
// chosen, Ceres run (multi-start, robust refits), the result checked and diagnosed, and the
// relinearised second solve.
#include "robocal/calib/identification.hpp"

#include "identification_detail.hpp"

#include "robocal/calib/conventions.hpp"

#include "robocal/core/parallel.hpp"

#include <ceres/ceres.h>
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <stdexcept>

namespace robocal::calib {

using namespace detail;  // the solve's parts (identification_detail.hpp)

const char* to_string(IdentificationStatus status) {
  switch (status) {
    case IdentificationStatus::kConverged:
      return "converged";
    case IdentificationStatus::kNotConverged:
      return "not_converged";
    case IdentificationStatus::kDiverged:
      return "diverged";
    case IdentificationStatus::kInvalidInput:
      return "invalid_input";
    case IdentificationStatus::kNotIdentifiable:
      return "not_identifiable";
  }
  return "unknown";
}

namespace {

// Evaluates every block at `params`: stacked whitened residuals and Jacobian (rows × P), and the
// row range of each pose block. Returns false when some pose cannot be solved.
bool evaluate_all(const Assembly& as, const Eigen::VectorXd& params, bool with_jacobian,
                  Eigen::VectorXd& r, Eigen::MatrixXd& J,
                  std::vector<std::pair<int, int>>* pose_rows = nullptr) {
  const auto P = params.size();
  r.resize(as.rows);
  if (with_jacobian) J.resize(as.rows, P);
  const double* blocks[] = {params.data()};
  // Each block into its own buffers (the pose blocks on as.threads workers), then stacked.
  struct Block {
    bool ok = false;
    Eigen::VectorXd r;
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> J;
  };
  const auto evaluate = [&](const ceres::CostFunction& cost, Block& b) {
    const int m = cost.num_residuals();
    b.r.resize(m);
    if (with_jacobian) b.J.resize(m, P);
    double* jac[] = {b.J.data()};
    b.ok = cost.Evaluate(blocks, b.r.data(), with_jacobian ? jac : nullptr);
  };
  std::vector<Block> pose_blocks(as.pose_costs.size());
  core::parallel_for(static_cast<int>(pose_blocks.size()), as.threads, [&](int i) {
    evaluate(*as.pose_costs[static_cast<std::size_t>(i)], pose_blocks[static_cast<std::size_t>(i)]);
  });
  int row = 0;
  const auto stack = [&](const Block& b) {
    if (!b.ok) return false;
    const auto m = static_cast<int>(b.r.size());
    r.segment(row, m) = b.r;
    if (with_jacobian) J.middleRows(row, m) = b.J;
    row += m;
    return true;
  };
  for (const Block& b : pose_blocks) {
    const int start = row;
    if (!stack(b)) return false;
    if (pose_rows) pose_rows->push_back({start, row - start});
  }
  for (const auto& c : as.distance_costs) {
    Block b;
    evaluate(*c, b);
    if (!stack(b)) return false;
  }
  return true;
}

// The request's sizes and options before anything is assembled: a nominal vector that does not
// fit the model, duplicate pose ids or an impossible thread count make the input invalid (the
// message says why); option vectors of the wrong size are a programming error and throw.
std::optional<std::string> check_request(const FramePredictor& model,
                                         const Eigen::VectorXd& nominal,
                                         const Measurements& measurements,
                                         const SolveOptions& options) {
  const std::size_t P = model.parameter_count();
  if (static_cast<std::size_t>(nominal.size()) != P || !nominal.allFinite())
    return fmt::format("nominal parameter vector has {} finite-checked entries, model has {}",
                       nominal.size(), P);
  auto check_size = [&](const auto& v, const char* what) {
    if (!v.empty() && v.size() != P)
      throw std::invalid_argument(fmt::format("{} must have one entry per parameter", what));
  };
  check_size(options.preference, "preference");
  check_size(options.prior_sigma, "prior_sigma");
  check_size(options.lower_bound, "lower_bound");
  check_size(options.upper_bound, "upper_bound");
  check_size(options.start_sigma, "start_sigma");

  std::set<std::string> ids;
  for (const auto& pose : measurements.poses)
    if (!ids.insert(pose.id).second)
      return fmt::format("pose id '{}' appears more than once", pose.id);

  if (options.threads < 1 || options.threads > 64)
    return fmt::format("threads must be in 1..64 (got {})", options.threads);
  return std::nullopt;
}

// The least-squares problem over the poses the nominal model can use: a pose with non-finite
// readings or observations, one the nominal model cannot solve or with malformed pixel groups is
// excluded with its reason (result.excluded); a distance naming a missing pose is ignored with a
// warning. Returns the measured positions beside their nominal predictions for the unit check.
MeasuredAndPredicted assemble_problem(const FramePredictor& model, const Eigen::VectorXd& nominal,
                                      const Measurements& measurements, const SolveOptions& options,
                                      Assembly& as, IdentificationResult& result) {
  as.threads = model.thread_safe() ? options.threads : 1;
  MeasuredAndPredicted positions;
  for (std::size_t k = 0; k < measurements.poses.size(); ++k) {
    const PoseMeasurement& pose = measurements.poses[k];
    if (!pose.actuators.allFinite()) {
      result.excluded.push_back({pose.id, "actuator readings are not finite (NaN or infinite)"});
      continue;
    }
    if (!std::all_of(pose.observations.begin(), pose.observations.end(), finite_observation)) {
      result.excluded.push_back(
          {pose.id, "an observation is not finite or has non-positive noise"});
      continue;
    }
    FramePrediction pred;
    std::string why;
    if (!model.predict(nominal, pose.actuators, static_cast<int>(k), false, pred, why)) {
      result.excluded.push_back(
          {pose.id, fmt::format("the nominal model cannot solve this pose: {}", why)});
      continue;
    }
    if (!valid_pixel_groups(pose, why) || !pixels_project(model, nominal, pose, pred, why)) {
      result.excluded.push_back({pose.id, why});
      continue;
    }
    as.slot_of[pose.id] = static_cast<int>(k);
    as.poses.push_back(&pose);
    if (!pose.observations.empty()) {
      as.pose_costs.push_back(std::make_unique<PoseCost>(model, pose, static_cast<int>(k)));
      as.rows += as.pose_costs.back()->num_residuals();
      for (const auto& obs : pose.observations)
        for (const auto& [group, sigma] : row_labels(obs)) as.label(group, sigma);
    }
    for (const auto& obs : pose.observations)
      if (auto p = observed_position(obs)) {
        positions.measured.push_back(*p);
        positions.predicted.emplace_back(pred.pose.translation());
      }
  }
  std::map<std::string, const PoseMeasurement*> by_id;
  for (const auto* p : as.poses) by_id[p->id] = p;
  for (const auto& d : measurements.distances) {
    if (!by_id.count(d.first) || !by_id.count(d.second)) {
      result.warnings.push_back(fmt::format(
          "distance {}–{} ignored: one of its poses is missing or excluded", d.first, d.second));
      continue;
    }
    as.distance_costs.push_back(
        std::make_unique<DistanceCost>(model, *by_id[d.first], as.slot_of.at(d.first),
                                       *by_id[d.second], as.slot_of.at(d.second), d.observation));
    as.rows += 1;
    as.label(kDistanceRows, d.observation.sigma);
  }
  for (std::size_t g = 0; g < as.groups.size(); ++g)
    as.groups[g].stated_sigma = median_of(as.stated[g]);
  return positions;
}

// The parameters the user lets change (every one when none is named).
std::vector<std::size_t> candidate_indices(const SolveOptions& options, std::size_t P) {
  std::vector<std::size_t> candidates = options.candidates;
  if (candidates.empty())
    for (std::size_t i = 0; i < P; ++i) candidates.push_back(i);
  for (std::size_t c : candidates)
    if (c >= P) throw std::invalid_argument("candidate parameter index out of range");
  return candidates;
}

// The candidates' columns of the whitened Jacobian at the linearisation point, what the rank
// analysis reads: their names, their visiting preference (`keep` first) and how many of them
// change the measurements at all.
struct CandidateColumns {
  Eigen::MatrixXd Jc;
  std::vector<std::string> names;
  std::vector<int> preference;
  std::size_t with_effect = 0;
};

CandidateColumns candidate_columns(const Eigen::MatrixXd& J,
                                   const std::vector<std::size_t>& candidates,
                                   const std::vector<std::string>& names,
                                   const SolveOptions& options,
                                   const std::vector<std::size_t>& keep) {
  CandidateColumns cc;
  cc.Jc.resize(J.rows(), static_cast<Eigen::Index>(candidates.size()));
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    cc.Jc.col(static_cast<Eigen::Index>(k)) = J.col(static_cast<Eigen::Index>(candidates[k]));
    cc.names.push_back(names[candidates[k]]);
    const int pref = options.preference.empty() ? 0 : options.preference[candidates[k]];
    const bool kept = std::find(keep.begin(), keep.end(), candidates[k]) != keep.end();
    if (!options.preference.empty() || !keep.empty())
      cc.preference.push_back(kept ? pref - (1 << 20) : pref);
  }
  const Eigen::VectorXd norms = cc.Jc.colwise().norm();
  const double top = norms.size() ? norms.maxCoeff() : 0.0;
  for (Eigen::Index k = 0; k < norms.size(); ++k)
    cc.with_effect += norms(k) > options.identifiability.no_effect_tolerance * top ? 1 : 0;
  return cc;
}

// Candidates with a prior (a tolerance) that change the measurements: priors are information
// too.
std::size_t candidates_with_prior(const std::vector<std::size_t>& candidates,
                                  const SolveOptions& options,
                                  const IdentifiabilityReport& report) {
  std::size_t with_prior = 0;
  for (std::size_t k = 0; k < candidates.size(); ++k)
    if (!options.prior_sigma.empty() && options.prior_sigma[candidates[k]] > 0.0 &&
        !std::binary_search(report.no_effect.begin(), report.no_effect.end(), k))
      ++with_prior;
  return with_prior;
}

// With little data (fewer equations than free parameters with an effect) the data determine
// only `rank` combinations: the weak directions are left to the gauge (or, with priors on every
// candidate, to the priors: `map_everything`), the gauge is chosen over the measured area, and
// result.gauge says so in words. Updates result.identifiability and result.limited_data.
void decide_gauge(const FramePredictor& model, const Eigen::VectorXd& linearisation,
                  const Assembly& as, const std::vector<std::size_t>& candidates,
                  const CandidateColumns& cc, const SolveOptions& options,
                  const std::vector<std::size_t>& keep, bool map_everything,
                  IdentificationResult& result) {
  const std::size_t with_effect = cc.with_effect;
  if (static_cast<std::size_t>(as.rows) < with_effect && !map_everything &&
      options.identifiability.rank_tolerance < options.identifiability.ill_conditioning_ratio) {
    // Little data: keep only the directions this design separates well (the ill-conditioning
    // ratio as rank tolerance), so the gauge holds the weak ones instead of estimating them
    // from noise (7 bed heights on the linear delta: without this, base tilt and rod lengths
    // changed by 65 mrad and 8 mm to fit 10 µm of noise).
    IdentifiabilityOptions strict = options.identifiability;
    strict.rank_tolerance = options.identifiability.ill_conditioning_ratio;
    result.identifiability = analyze_identifiability(cc.Jc, cc.names, strict, cc.preference);
  }
  std::string gauge_why;
  if (static_cast<std::size_t>(as.rows) < with_effect && !map_everything && keep.empty() &&
      !options.gauge_sigma.empty() && !result.identifiability.redundancies.empty())
    gauge_why =
        choose_little_data_gauge(model, linearisation, as.poses, cc.Jc, candidates, cc.names,
                                 options, result.identifiability, result.estimator);
  if (static_cast<std::size_t>(as.rows) < with_effect) {
    result.limited_data = true;
    std::string held;
    for (std::size_t k : result.identifiability.redundant)
      if (!std::binary_search(result.identifiability.no_effect.begin(),
                              result.identifiability.no_effect.end(), k))
        held += (held.empty() ? "" : ", ") + cc.names[k];
    result.gauge =
        map_everything
            ? fmt::format(
                  "{} equations for {} free parameters: the data determine {} "
                  "combinations; the robot file's tolerances (priors) supply the rest, so "
                  "every parameter is estimated (MAP) and the held directions stay near "
                  "nominal within their tolerance",
                  as.rows, with_effect, result.identifiability.rank)
            : fmt::format(
                  "{} equations for {} free parameters: the data determine {} "
                  "combinations, so {} parameters are estimated and {} are held at their "
                  "nominal values (the gauge, chosen for this robot and this data: each "
                  "held parameter moves the measurements like a combination of estimated "
                  "ones, see the redundancies){}{}{}",
                  as.rows, with_effect,
                  result.estimator.made ? result.estimator.data_rank : result.identifiability.rank,
                  result.identifiability.rank, with_effect - result.identifiability.rank,
                  held.empty() ? "" : ": ", held, gauge_why);
  }
}

// The parameters estimated (result.estimated): every candidate with an effect under
// `map_everything`, else the identifiable ones and those in `keep`. The message when that is
// not possible, or nothing.
std::optional<std::string> choose_estimated(const std::vector<std::size_t>& candidates,
                                            const SolveOptions& options,
                                            const std::vector<std::size_t>& keep,
                                            bool map_everything, IdentificationResult& result) {
  if (map_everything) {
    // Every candidate that has an effect is estimated; the prior makes the problem well posed.
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (!std::binary_search(result.identifiability.no_effect.begin(),
                              result.identifiability.no_effect.end(), k))
        result.estimated.push_back(candidates[k]);
    bool all_priors = !options.prior_sigma.empty();
    for (std::size_t i : result.estimated) all_priors = all_priors && options.prior_sigma[i] > 0.0;
    if (!all_priors && options.estimate_redundant)
      return "estimate_redundant needs a prior (prior_sigma > 0) on every candidate";
  } else {
    std::vector<bool> estimate_it(candidates.size(), false);
    for (std::size_t k : result.identifiability.identifiable) estimate_it[k] = true;
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (std::find(keep.begin(), keep.end(), candidates[k]) != keep.end()) estimate_it[k] = true;
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (estimate_it[k]) result.estimated.push_back(candidates[k]);
  }
  if (result.estimated.empty()) return "no identifiable parameter among the candidates";
  return std::nullopt;
}

// What every Ceres solve of one identify_at shares: the assembled costs, the parameters held
// constant (those not estimated), the priors and the bounds.
struct CeresSetup {
  const Assembly& as;
  const SolveOptions& options;
  const Eigen::VectorXd& nominal;
  const std::vector<std::size_t>& estimated;
  std::vector<int> held;
  std::vector<std::pair<std::size_t, double>> prior_terms;
};

CeresSetup ceres_setup(const Assembly& as, const SolveOptions& options,
                       const Eigen::VectorXd& nominal, const std::vector<std::size_t>& estimated,
                       std::size_t P) {
  CeresSetup setup{as, options, nominal, estimated, {}, {}};
  {
    std::vector<bool> est(P, false);
    for (std::size_t i : estimated) est[i] = true;
    for (std::size_t i = 0; i < P; ++i)
      if (!est[i]) setup.held.push_back(static_cast<int>(i));
  }
  if (!options.prior_sigma.empty())
    for (std::size_t i : estimated)
      if (options.prior_sigma[i] > 0.0) setup.prior_terms.emplace_back(i, options.prior_sigma[i]);
  return setup;
}

// One Levenberg–Marquardt solve from `x` over the full vector with the non-estimated entries
// held constant. `row_scale` (one per pose-cost row, may be empty): the robust loss counts in
// these units.
Eigen::VectorXd solve_from(const CeresSetup& setup, Eigen::VectorXd x,
                           ceres::Solver::Summary& summary,
                           const std::vector<double>& row_scale = {}) {
  const Assembly& as = setup.as;
  const SolveOptions& options = setup.options;
  const auto P = static_cast<std::size_t>(setup.nominal.size());
  ceres::Problem::Options popt;
  popt.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popt.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  std::vector<const PoseCost*> ahead;
  ahead.reserve(as.pose_costs.size());
  for (const auto& c : as.pose_costs) ahead.push_back(c.get());
  EvaluateAhead evaluate_ahead(std::move(ahead), x.data(), as.threads);
  if (as.threads > 1) popt.evaluation_callback = &evaluate_ahead;
  ceres::Problem problem(popt);
  std::vector<std::unique_ptr<ceres::CostFunction>> scaled;
  int first_row = 0;
  for (const auto& c : as.pose_costs) {
    ceres::LossFunction* loss = nullptr;
    if (options.robust_loss == RobustLoss::kHuber)
      loss = new ceres::HuberLoss(options.robust_scale);
    if (options.robust_loss == RobustLoss::kCauchy)
      loss = new ceres::CauchyLoss(options.robust_scale);
    ceres::CostFunction* cost = c.get();
    if (!row_scale.empty()) {
      Eigen::VectorXd inverse(c->num_residuals());
      for (int i = 0; i < c->num_residuals(); ++i)
        inverse(i) = 1.0 / row_scale[static_cast<std::size_t>(first_row + i)];
      scaled.push_back(std::make_unique<RowScaledCost>(*c, std::move(inverse)));
      cost = scaled.back().get();
    }
    first_row += c->num_residuals();
    problem.AddResidualBlock(cost, loss, x.data());
  }
  for (const auto& c : as.distance_costs) problem.AddResidualBlock(c.get(), nullptr, x.data());
  std::unique_ptr<ceres::CostFunction> prior;
  if (!setup.prior_terms.empty()) {
    prior = std::make_unique<PriorCost>(setup.nominal, setup.prior_terms);
    problem.AddResidualBlock(prior.get(), nullptr, x.data());
  }
  if (!setup.held.empty())
    problem.SetManifold(x.data(), new ceres::SubsetManifold(static_cast<int>(P), setup.held));
  for (std::size_t i : setup.estimated) {
    if (!options.lower_bound.empty() && std::isfinite(options.lower_bound[i]))
      problem.SetParameterLowerBound(x.data(), static_cast<int>(i), options.lower_bound[i]);
    if (!options.upper_bound.empty() && std::isfinite(options.upper_bound[i]))
      problem.SetParameterUpperBound(x.data(), static_cast<int>(i), options.upper_bound[i]);
  }
  ceres::Solver::Options sopt;
  sopt.linear_solver_type = ceres::DENSE_QR;
  sopt.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  sopt.function_tolerance = options.function_tolerance;
  sopt.gradient_tolerance = options.gradient_tolerance;
  sopt.parameter_tolerance = options.parameter_tolerance;
  sopt.max_num_iterations = options.max_iterations;
  sopt.num_threads = 1;
  ceres::Solve(sopt, &problem, &summary);
  return x;
}

// The lowest-objective usable solve so far (nominal and unusable until one is found).
struct BestSolve {
  Eigen::VectorXd x;
  double cost = INFINITY;
  bool usable = false;
  ceres::Solver::Summary summary;
};

// The solve from `start` and from SolveOptions::multi_start perturbed starts; the lowest
// objective that leaves every pose solvable wins.
BestSolve multi_start(const CeresSetup& setup, const Eigen::VectorXd& start) {
  const SolveOptions& options = setup.options;
  std::mt19937 rng(options.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  BestSolve best;
  best.x = setup.nominal;
  const int starts = 1 + std::max(0, options.multi_start);
  for (int s = 0; s < starts; ++s) {
    Eigen::VectorXd x0 = start;
    if (s > 0) {
      for (std::size_t i : setup.estimated) {
        const double sig = !options.start_sigma.empty()   ? options.start_sigma[i]
                           : !options.prior_sigma.empty() ? options.prior_sigma[i]
                                                          : 0.0;
        x0(static_cast<Eigen::Index>(i)) += sig * n01(rng);
      }
    }
    ceres::Solver::Summary summary;
    const Eigen::VectorXd x = solve_from(setup, x0, summary);
    Eigen::VectorXd rx;
    Eigen::MatrixXd unused;
    const bool solvable = summary.IsSolutionUsable() && x.allFinite() &&
                          evaluate_all(setup.as, x, false, rx, unused) && rx.allFinite();
    // Compare with the objective actually minimised (robust loss included).
    const double cost = solvable ? summary.final_cost : INFINITY;
    if (solvable && cost < best.cost) {
      best.x = x;
      best.cost = cost;
      best.usable = true;
      best.summary = summary;
    }
  }
  return best;
}

// Robust loss at the estimated noise: refit from the first robust fit with the threshold in
// units of each observation type's outlier-proof residual scale there, and again from that
// fit (its residuals are no longer spread by the outliers) until the scales settle. Records the
// scales used in result.robust_loss_noise_scale.
void refit_at_estimated_noise(const CeresSetup& setup, BestSolve& best,
                              IdentificationResult& result) {
  const Assembly& as = setup.as;
  const SolveOptions& options = setup.options;
  int pose_cost_rows = 0;
  for (const auto& c : as.pose_costs) pose_cost_rows += c->num_residuals();
  for (int pass = 0; pass < 4 && best.usable && pose_cost_rows > 0 &&
                     options.robust_loss != RobustLoss::kNone && !options.keep_stated_noise;
       ++pass) {
    Eigen::VectorXd r1;
    Eigen::MatrixXd unused;
    if (evaluate_all(as, best.x, false, r1, unused)) {
      const auto scale = robust_row_scales(r1, as.row_group, as.groups.size(), pose_cost_rows);
      bool settled = !result.robust_loss_noise_scale.empty();
      for (std::size_t g = 0; settled && g < scale.size(); ++g)
        settled = std::abs(scale[g] / result.robust_loss_noise_scale[g] - 1.0) < 0.02;
      if (settled) break;
      std::vector<double> row_scale(static_cast<std::size_t>(pose_cost_rows));
      for (int i = 0; i < pose_cost_rows; ++i)
        row_scale[static_cast<std::size_t>(i)] =
            scale[static_cast<std::size_t>(as.row_group[static_cast<std::size_t>(i)])];
      ceres::Solver::Summary summary;
      const Eigen::VectorXd x = solve_from(setup, best.x, summary, row_scale);
      Eigen::VectorXd rx;
      if (summary.IsSolutionUsable() && x.allFinite() && evaluate_all(as, x, false, rx, unused) &&
          rx.allFinite()) {
        best.x = x;
        best.cost = summary.final_cost;
        best.summary = summary;
        result.robust_loss_noise_scale = scale;
        continue;
      }
    }
    break;
  }
}

// Wall time since `t0` (IdentificationResult::solve_seconds).
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// One solve. The identifiability analysis is done at `linearisation` (the nominal model for the
// first solve, the first estimate for the relinearised one); the parameters in `keep` are
// estimated whatever the analysis says (they are visited first, so the analysis only adds to
// them). Priors, pose exclusion and result.nominal refer to `nominal`. With `only_if_added`, it
// stops once the analysis has chosen the estimated set when that set adds nothing to `keep`: the
// relinearisation keeps the first estimate then, whatever a solve would give.
IdentificationResult identify_at(const FramePredictor& model, const Eigen::VectorXd& nominal,
                                 const Eigen::VectorXd& linearisation,
                                 const Measurements& measurements, const SolveOptions& options,
                                 const std::vector<std::size_t>& keep, bool only_if_added = false) {
  const auto t0 = std::chrono::steady_clock::now();
  IdentificationResult result;
  const std::size_t P = model.parameter_count();
  result.names = model.parameter_names();
  result.labels = model.parameter_labels();
  result.nominal = nominal;
  result.estimate = nominal;
  auto invalid = [&](std::string why) {
    result.status = IdentificationStatus::kInvalidInput;
    result.message = std::move(why);
    return result;
  };
  if (auto why = check_request(model, nominal, measurements, options)) return invalid(*why);

  // 1. The problem over the usable poses, then the checks that need it: units off by 1000, then
  // convention swaps (quaternion order, degrees, inverted poses) against the nominal model.
  Assembly as;
  const MeasuredAndPredicted positions =
      assemble_problem(model, nominal, measurements, options, as, result);
  if (auto why = position_units_mismatch(positions)) return invalid(*why);
  if (auto why = probe_height_units_mismatch(model, nominal, as)) return invalid(*why);
  if (auto swap = check_conventions(model, nominal, measurements)) return invalid(swap->message);

  // 2. Identifiability over the candidates at the linearisation point, then the estimated set.
  const std::vector<std::size_t> candidates = candidate_indices(options, P);
  result.candidates = candidates;
  const std::size_t poses_used = as.pose_costs.size();
  if (as.rows == 0) return invalid("no usable measurements (all poses excluded or empty)");
  result.equations = as.rows;
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  if (!evaluate_all(as, linearisation, true, r, J))
    return invalid(&linearisation == &nominal
                       ? "a pose failed to solve while assembling the Jacobian at the nominal model"
                       : "a pose failed to solve while assembling the Jacobian at the estimate");
  const CandidateColumns cc = candidate_columns(J, candidates, result.names, options, keep);
  result.identifiability =
      analyze_identifiability(cc.Jc, cc.names, options.identifiability, cc.preference);
  // The count check comes after the analysis: with little data (fewer equations than free
  // parameters with an effect) the data determine only `rank` combinations; those are estimated
  // and the rest held at nominal — an automatically chosen gauge, explained in words. Priors are
  // information too: with a prior on every candidate that has an effect, everything is estimated
  // (MAP). Refused only when no parameter changes the measurements at all.
  const std::size_t with_prior = candidates_with_prior(candidates, options, result.identifiability);
  if (result.identifiability.rank == 0 && with_prior == 0) {
    result.status = IdentificationStatus::kNotIdentifiable;
    result.message = fmt::format(
        "nothing is identifiable: {} usable poses give {} measurement equations, and none of the "
        "{} free parameters changes them",
        poses_used, as.rows, candidates.size());
    return result;
  }
  const bool priors_complete = with_prior == cc.with_effect && cc.with_effect > 0;
  const bool map_everything =
      options.estimate_redundant ||
      (priors_complete && static_cast<std::size_t>(as.rows) < cc.with_effect);
  decide_gauge(model, linearisation, as, candidates, cc, options, keep, map_everything, result);
  if (auto why = choose_estimated(candidates, options, keep, map_everything, result))
    return invalid(*why);
  if (only_if_added &&
      std::all_of(result.estimated.begin(), result.estimated.end(), [&](std::size_t i) {
        return std::find(keep.begin(), keep.end(), i) != keep.end();
      }))
    return result;

  // 3. Ceres problem over the full vector with the non-estimated entries held constant.
  const CeresSetup setup = ceres_setup(as, options, nominal, result.estimated, P);
  Eigen::VectorXd start = options.start.size() ? options.start : linearisation;
  if (static_cast<std::size_t>(start.size()) != P)
    throw std::invalid_argument("start must have one entry per parameter");
  {
    Eigen::VectorXd r0;
    Eigen::MatrixXd unused;
    if (evaluate_all(as, start, false, r0, unused))
      result.initial_cost = 0.5 * r0.squaredNorm();
    else
      result.initial_cost = INFINITY;
  }
  BestSolve best = multi_start(setup, start);
  refit_at_estimated_noise(setup, best, result);
  result.starts_run = 1 + std::max(0, options.multi_start);
  result.iterations = static_cast<int>(best.summary.iterations.size());

  // 4. Divergence guard: keep the nominal model when the solve failed or made the fit worse.
  Eigen::VectorXd rb;
  Eigen::MatrixXd Jb;
  std::vector<std::pair<int, int>> pose_rows;
  const bool have_best = best.usable && evaluate_all(as, best.x, true, rb, Jb, &pose_rows);
  if (!have_best) {
    result.status = IdentificationStatus::kDiverged;
    result.message =
        fmt::format("the solve diverged or left a pose unsolvable ({}); the nominal model is kept",
                    best.summary.message.empty() ? "no usable solution" : best.summary.message);
    result.estimate = nominal;
    result.solve_seconds = seconds_since(t0);
    return result;
  }
  result.final_cost = 0.5 * rb.squaredNorm();
  result.objective = best.cost;
  if (options.robust_loss == RobustLoss::kNone && setup.prior_terms.empty() &&
      result.final_cost > result.initial_cost * (1.0 + 1e-9)) {
    result.status = IdentificationStatus::kDiverged;
    result.message =
        fmt::format("the solve increased the cost ({:.6g} -> {:.6g}); the nominal model is kept",
                    result.initial_cost, result.final_cost);
    result.estimate = nominal;
    return result;
  }
  result.estimate = best.x;
  result.status = best.summary.termination_type == ceres::CONVERGENCE
                      ? IdentificationStatus::kConverged
                      : IdentificationStatus::kNotConverged;
  result.message = fmt::format("{} parameters estimated from {} poses ({} equations): {}",
                               result.estimated.size(), poses_used, as.rows, best.summary.message);

  // 5. Diagnostics at the estimate.
  diagnose_estimate(model, nominal, as, {best.x, rb, Jb, pose_rows, setup.prior_terms},
                    measurements.distances, options, result);
  result.solve_seconds = seconds_since(t0);
  return result;
}

bool usable(const IdentificationResult& r) {
  return r.status == IdentificationStatus::kConverged ||
         r.status == IdentificationStatus::kNotConverged;
}

}  // namespace

namespace {

// One relinearisation round (SolveOptions::relinearise) after the solve `first`.
IdentificationResult relinearise_once(const FramePredictor& model, const Eigen::VectorXd& nominal,
                                      const Measurements& measurements, const SolveOptions& options,
                                      IdentificationResult first) {
  // Second solve from the first estimate over the first set plus what became identifiable there.
  SolveOptions again = options;
  again.identifiability.rank_tolerance = options.relinearise_rank_tolerance;
  again.start = first.estimate;
  again.multi_start = 0;
  // From a converged first estimate the second solve takes a few dozen iterations (Delta bench:
  // under 30); one still moving after `relinearise_max_iterations` is crawling along a curved
  // valley and will be discarded below, so it should not cost minutes (pixel route: 200
  // iterations over 35 000 equations took up to 3 minutes).
  again.max_iterations = std::min(options.max_iterations, options.relinearise_max_iterations);
  IdentificationResult second =
      identify_at(model, nominal, first.estimate, measurements, again, first.estimated, true);
  RelinearisationReport report;
  report.attempted = true;
  for (std::size_t i : second.estimated)
    if (std::find(first.estimated.begin(), first.estimated.end(), i) == first.estimated.end())
      report.added.push_back(i);
  const double seconds = first.solve_seconds + second.solve_seconds;
  // The first result stands; the report says why (nothing is added then).
  auto keep_first = [&](std::string why) {
    report.added.clear();
    report.message = std::move(why);
    first.relinearisation = report;
    first.solve_seconds = seconds;
    return std::move(first);
  };
  if (report.added.empty())
    return keep_first("relinearised at the estimate: no further parameter became identifiable");
  std::string added_names;
  for (std::size_t i : report.added)
    added_names += (added_names.empty() ? "" : ", ") + first.names[i];
  // A second solve that does not converge is crawling along a curved valley of weakly
  // determined directions (seen with a tool orientation that only the plate's slight rotation
  // separates from the base's): its end point is arbitrary, keep the first estimate.
  if (second.status != IdentificationStatus::kConverged)
    return keep_first(fmt::format(
        "relinearised at the estimate, {} became identifiable, but the second solve did not "
        "converge ({}); the first estimate is kept",
        added_names, second.message));
  report.cost_before = first.final_cost;
  report.cost_after = second.final_cost;
  report.predicted_before = first.predicted.position_rms_overall;
  report.predicted_after = second.predicted.position_rms_overall;
  const bool inflated =
      !second.uncertainty.ok ||
      (first.uncertainty.ok && report.predicted_after > options.relinearise_max_uncertainty_growth *
                                                            report.predicted_before);
  report.accepted = !inflated;
  const std::string message = fmt::format(
      "relinearised at the estimate: {} parameter(s) held at nominal by the first analysis became "
      "identifiable ({}); cost {:.6g} -> {:.6g}, predicted end-effector uncertainty {:.3g} -> "
      "{:.3g} mm: {}",
      report.added.size(), added_names, report.cost_before, report.cost_after,
      1e3 * report.predicted_before, 1e3 * report.predicted_after,
      report.accepted ? "estimated"
                      : "they are too weakly determined by this data and stay at nominal");
  if (!report.accepted) return keep_first(message);
  report.message = message;
  // The plain-words analysis stays the one at the nominal model (what the design can separate);
  // the estimated set and everything after it come from the second solve.
  second.identifiability = std::move(first.identifiability);
  second.initial_cost = first.initial_cost;
  second.iterations += first.iterations;
  second.starts_run = first.starts_run;
  second.solve_seconds = seconds;
  second.excluded = std::move(first.excluded);
  second.relinearisation = report;
  second.message += "; " + report.message;
  return second;
}

}  // namespace

IdentificationResult identify(const FramePredictor& model, const Eigen::VectorXd& nominal,
                              const Measurements& measurements, const SolveOptions& options) {
  IdentificationResult result = identify_at(model, nominal, nominal, measurements, options, {});
  if (!options.relinearise || options.estimate_redundant || !usable(result)) return result;
  // A set smaller than the data's rank was chosen for what it predicts: the
  // relinearised analysis would add back what was held on purpose.
  if (result.estimator.made &&
      result.estimator.chosen.estimated.size() < result.estimator.data_rank)
    return result;
  // One round: a second round at the relinearised estimate changed the Delta's bench figures by
  // a few per cent at most (identify_bench, three truths), not worth another solve.
  return relinearise_once(model, nominal, measurements, options, std::move(result));
}

bool identification_jacobian(const FramePredictor& model, const Eigen::VectorXd& params,
                             const Measurements& measurements, Eigen::MatrixXd& jacobian,
                             std::string& why) {
  Assembly as;
  std::map<std::string, int> slot_of;
  for (std::size_t k = 0; k < measurements.poses.size(); ++k) {
    const PoseMeasurement& pose = measurements.poses[k];
    slot_of[pose.id] = static_cast<int>(k);
    if (!valid_pixel_groups(pose, why)) return false;
    if (pose.observations.empty()) continue;
    as.pose_costs.push_back(std::make_unique<PoseCost>(model, pose, static_cast<int>(k)));
    as.rows += as.pose_costs.back()->num_residuals();
  }
  for (const auto& d : measurements.distances) {
    const auto a = slot_of.find(d.first);
    const auto b = slot_of.find(d.second);
    if (a == slot_of.end() || b == slot_of.end()) {
      why = fmt::format("distance {}-{} names a pose that is not in the measurements", d.first,
                        d.second);
      return false;
    }
    as.distance_costs.push_back(std::make_unique<DistanceCost>(
        model, measurements.poses[static_cast<std::size_t>(a->second)], a->second,
        measurements.poses[static_cast<std::size_t>(b->second)], b->second, d.observation));
    as.rows += 1;
  }
  Eigen::VectorXd r;
  if (!evaluate_all(as, params, true, r, jacobian)) {
    why = "a pose cannot be predicted at these parameters";
    return false;
  }
  return true;
}

}  // namespace robocal::calib
