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
  if (static_cast<std::size_t>(nominal.size()) != P || !nominal.allFinite())
    return invalid(fmt::format(
        "nominal parameter vector has {} finite-checked entries, model has {}", nominal.size(), P));
  auto check_size = [&](const auto& v, const char* what) {
    if (!v.empty() && v.size() != P)
      throw std::invalid_argument(fmt::format("{} must have one entry per parameter", what));
  };
  check_size(options.preference, "preference");
  check_size(options.prior_sigma, "prior_sigma");
  check_size(options.lower_bound, "lower_bound");
  check_size(options.upper_bound, "upper_bound");
  check_size(options.start_sigma, "start_sigma");

  // 1. Input checks.
  std::set<std::string> ids;
  for (const auto& pose : measurements.poses)
    if (!ids.insert(pose.id).second)
      return invalid(fmt::format("pose id '{}' appears more than once", pose.id));

  if (options.threads < 1 || options.threads > 64)
    return invalid(fmt::format("threads must be in 1..64 (got {})", options.threads));
  Assembly as;
  as.threads = model.thread_safe() ? options.threads : 1;
  std::map<std::string, int> slot_of;
  std::vector<Eigen::Vector3d> measured_pts;
  std::vector<Eigen::Vector3d> predicted_pts;
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
    slot_of[pose.id] = static_cast<int>(k);
    as.poses.push_back(&pose);
    if (!pose.observations.empty()) {
      as.pose_costs.push_back(std::make_unique<PoseCost>(model, pose, static_cast<int>(k)));
      as.rows += as.pose_costs.back()->num_residuals();
      for (const auto& obs : pose.observations)
        for (const auto& [group, sigma] : row_labels(obs)) as.label(group, sigma);
    }
    for (const auto& obs : pose.observations)
      if (auto p = observed_position(obs)) {
        measured_pts.push_back(*p);
        predicted_pts.emplace_back(pred.pose.translation());
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
    as.distance_costs.push_back(std::make_unique<DistanceCost>(model, *by_id[d.first],
                                                               slot_of[d.first], *by_id[d.second],
                                                               slot_of[d.second], d.observation));
    as.rows += 1;
    as.label(kDistanceRows, d.observation.sigma);
  }
  if (measured_pts.size() >= 3) {
    const double ratio = spread(measured_pts) / std::max(spread(predicted_pts), 1e-300);
    if (ratio > 300.0 || ratio < 1.0 / 300.0)
      return invalid(fmt::format(
          "the measured positions spread {:.4g} times as far as the model predicts: units are "
          "probably mismatched by 1000 (millimetres vs metres); convert the measurements to metres",
          ratio));
  }

  // 1a. Probe heights in millimetres declared as metres: at the nominal model a height is off by
  // at most millimetres; a value 1000x too large is off by decimetres to metres.
  {
    std::vector<double> misfit;
    std::vector<double> misfit_mm;
    const PoseMeasurement* worst = nullptr;
    double worst_misfit = 0.0;
    for (const auto* pose : as.poses) {
      FramePrediction pred;
      std::string why;
      if (!model.predict(nominal, pose->actuators, slot_of[pose->id], false, pred, why)) continue;
      for (const auto& obs : pose->observations)
        if (const auto* ph = std::get_if<ProbeHeightObservation>(&obs)) {
          const double predicted = ph->normal.dot(pred.pose.translation()) - ph->offset;
          misfit.push_back(std::abs(ph->measured_height - predicted));
          misfit_mm.push_back(std::abs(1e-3 * ph->measured_height - predicted));
          if (misfit.back() > worst_misfit) {
            worst_misfit = misfit.back();
            worst = pose;
          }
        }
    }
    if (!misfit.empty() && median_of(misfit) > 0.05 && median_of(misfit_mm) < 0.01)
      return invalid(fmt::format(
          "probe heights are implausible in metres: median {:.3g} m from the nominal model, {:.3g} "
          "m if they were millimetres (largest at pose '{}'{}); declare units: {{length: mm}} or "
          "convert them",
          median_of(misfit), median_of(misfit_mm), worst->id,
          worst->line > 0 ? fmt::format(", line {}", worst->line) : ""));
  }

  // 1b. Convention swaps (quaternion order, degrees, inverted poses) against the nominal model.
  if (auto swap = check_conventions(model, nominal, measurements)) return invalid(swap->message);

  // 2. Identifiability over the candidates.
  std::vector<std::size_t> candidates = options.candidates;
  if (candidates.empty())
    for (std::size_t i = 0; i < P; ++i) candidates.push_back(i);
  for (std::size_t c : candidates)
    if (c >= P) throw std::invalid_argument("candidate parameter index out of range");
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
  Eigen::MatrixXd Jc(J.rows(), static_cast<Eigen::Index>(candidates.size()));
  std::vector<std::string> cand_names;
  std::vector<int> cand_pref;
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    Jc.col(static_cast<Eigen::Index>(k)) = J.col(static_cast<Eigen::Index>(candidates[k]));
    cand_names.push_back(result.names[candidates[k]]);
    const int pref = options.preference.empty() ? 0 : options.preference[candidates[k]];
    const bool kept = std::find(keep.begin(), keep.end(), candidates[k]) != keep.end();
    if (!options.preference.empty() || !keep.empty())
      cand_pref.push_back(kept ? pref - (1 << 20) : pref);
  }
  std::size_t with_effect = 0;
  {
    const Eigen::VectorXd norms = Jc.colwise().norm();
    const double top = norms.size() ? norms.maxCoeff() : 0.0;
    for (Eigen::Index k = 0; k < norms.size(); ++k)
      with_effect += norms(k) > options.identifiability.no_effect_tolerance * top ? 1 : 0;
  }
  result.identifiability =
      analyze_identifiability(Jc, cand_names, options.identifiability, cand_pref);
  for (std::size_t g = 0; g < as.groups.size(); ++g)
    as.groups[g].stated_sigma = median_of(as.stated[g]);
  // The count check comes after the analysis: with little data (fewer equations than free
  // parameters with an effect) the data determine only `rank` combinations; those are estimated
  // and the rest held at nominal — an automatically chosen gauge, explained in words. Priors are
  // information too: with a prior on every candidate that has an effect, everything is estimated
  // (MAP). Refused only when no parameter changes the measurements at all.
  std::size_t with_prior = 0;
  for (std::size_t k = 0; k < candidates.size(); ++k)
    if (!options.prior_sigma.empty() && options.prior_sigma[candidates[k]] > 0.0 &&
        !std::binary_search(result.identifiability.no_effect.begin(),
                            result.identifiability.no_effect.end(), k))
      ++with_prior;
  if (result.identifiability.rank == 0 && with_prior == 0) {
    result.status = IdentificationStatus::kNotIdentifiable;
    result.message = fmt::format(
        "nothing is identifiable: {} usable poses give {} measurement equations, and none of the "
        "{} free parameters changes them",
        poses_used, as.rows, candidates.size());
    return result;
  }
  const bool priors_complete = with_prior == with_effect && with_effect > 0;
  const bool map_everything = options.estimate_redundant ||
                              (priors_complete && static_cast<std::size_t>(as.rows) < with_effect);
  if (static_cast<std::size_t>(as.rows) < with_effect && !map_everything &&
      options.identifiability.rank_tolerance < options.identifiability.ill_conditioning_ratio) {
    // Little data: keep only the directions this design separates well (the ill-conditioning
    // ratio as rank tolerance), so the gauge holds the weak ones instead of estimating them
    // from noise (7 bed heights on the linear delta: without this, base tilt and rod lengths
    // changed by 65 mrad and 8 mm to fit 10 µm of noise).
    IdentifiabilityOptions strict = options.identifiability;
    strict.rank_tolerance = options.identifiability.ill_conditioning_ratio;
    result.identifiability = analyze_identifiability(Jc, cand_names, strict, cand_pref);
  }
  std::string gauge_why;
  if (static_cast<std::size_t>(as.rows) < with_effect && !map_everything && keep.empty() &&
      !options.gauge_sigma.empty() && !result.identifiability.redundancies.empty())
    gauge_why = choose_little_data_gauge(model, linearisation, as.poses, Jc, candidates, cand_names,
                                         options, result.identifiability);
  if (static_cast<std::size_t>(as.rows) < with_effect) {
    result.limited_data = true;
    std::string held;
    for (std::size_t k : result.identifiability.redundant)
      if (!std::binary_search(result.identifiability.no_effect.begin(),
                              result.identifiability.no_effect.end(), k))
        held += (held.empty() ? "" : ", ") + cand_names[k];
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
                  as.rows, with_effect, result.identifiability.rank, result.identifiability.rank,
                  with_effect - result.identifiability.rank, held.empty() ? "" : ": ", held,
                  gauge_why);
  }
  if (map_everything) {
    // Every candidate that has an effect is estimated; the prior makes the problem well posed.
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (!std::binary_search(result.identifiability.no_effect.begin(),
                              result.identifiability.no_effect.end(), k))
        result.estimated.push_back(candidates[k]);
    bool all_priors = !options.prior_sigma.empty();
    for (std::size_t i : result.estimated) all_priors = all_priors && options.prior_sigma[i] > 0.0;
    if (!all_priors && options.estimate_redundant)
      return invalid("estimate_redundant needs a prior (prior_sigma > 0) on every candidate");
  } else {
    std::vector<bool> estimate_it(candidates.size(), false);
    for (std::size_t k : result.identifiability.identifiable) estimate_it[k] = true;
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (std::find(keep.begin(), keep.end(), candidates[k]) != keep.end()) estimate_it[k] = true;
    for (std::size_t k = 0; k < candidates.size(); ++k)
      if (estimate_it[k]) result.estimated.push_back(candidates[k]);
  }
  if (result.estimated.empty()) return invalid("no identifiable parameter among the candidates");
  if (only_if_added &&
      std::all_of(result.estimated.begin(), result.estimated.end(), [&](std::size_t i) {
        return std::find(keep.begin(), keep.end(), i) != keep.end();
      }))
    return result;

  // 3. Ceres problem over the full vector with the non-estimated entries held constant.
  std::vector<int> held;
  {
    std::vector<bool> est(P, false);
    for (std::size_t i : result.estimated) est[i] = true;
    for (std::size_t i = 0; i < P; ++i)
      if (!est[i]) held.push_back(static_cast<int>(i));
  }
  std::vector<std::pair<std::size_t, double>> prior_terms;
  if (!options.prior_sigma.empty())
    for (std::size_t i : result.estimated)
      if (options.prior_sigma[i] > 0.0) prior_terms.emplace_back(i, options.prior_sigma[i]);

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

  // `row_scale` (one per pose-cost row, may be empty): the robust loss counts in these units.
  auto solve_from = [&](Eigen::VectorXd x, ceres::Solver::Summary& summary,
                        const std::vector<double>& row_scale = {}) {
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
    if (!prior_terms.empty()) {
      prior = std::make_unique<PriorCost>(nominal, prior_terms);
      problem.AddResidualBlock(prior.get(), nullptr, x.data());
    }
    if (!held.empty())
      problem.SetManifold(x.data(), new ceres::SubsetManifold(static_cast<int>(P), held));
    for (std::size_t i : result.estimated) {
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
  };

  std::mt19937 rng(options.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::VectorXd best = nominal;
  double best_cost = INFINITY;
  bool best_usable = false;
  ceres::Solver::Summary best_summary;
  const int starts = 1 + std::max(0, options.multi_start);
  for (int s = 0; s < starts; ++s) {
    Eigen::VectorXd x0 = start;
    if (s > 0) {
      for (std::size_t i : result.estimated) {
        const double sig = !options.start_sigma.empty()   ? options.start_sigma[i]
                           : !options.prior_sigma.empty() ? options.prior_sigma[i]
                                                          : 0.0;
        x0(static_cast<Eigen::Index>(i)) += sig * n01(rng);
      }
    }
    ceres::Solver::Summary summary;
    const Eigen::VectorXd x = solve_from(x0, summary);
    Eigen::VectorXd rx;
    Eigen::MatrixXd unused;
    const bool solvable = summary.IsSolutionUsable() && x.allFinite() &&
                          evaluate_all(as, x, false, rx, unused) && rx.allFinite();
    // Compare with the objective actually minimised (robust loss included).
    const double cost = solvable ? summary.final_cost : INFINITY;
    if (solvable && cost < best_cost) {
      best = x;
      best_cost = cost;
      best_usable = true;
      best_summary = summary;
    }
  }
  // Robust loss at the estimated noise: refit from the first robust fit with the threshold in
  // units of each observation type's outlier-proof residual scale there, and again from that
  // fit (its residuals are no longer spread by the outliers) until the scales settle.
  int pose_cost_rows = 0;
  for (const auto& c : as.pose_costs) pose_cost_rows += c->num_residuals();
  for (int pass = 0; pass < 4 && best_usable && pose_cost_rows > 0 &&
                     options.robust_loss != RobustLoss::kNone && !options.keep_stated_noise;
       ++pass) {
    Eigen::VectorXd r1;
    Eigen::MatrixXd unused;
    if (evaluate_all(as, best, false, r1, unused)) {
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
      const Eigen::VectorXd x = solve_from(best, summary, row_scale);
      Eigen::VectorXd rx;
      if (summary.IsSolutionUsable() && x.allFinite() && evaluate_all(as, x, false, rx, unused) &&
          rx.allFinite()) {
        best = x;
        best_cost = summary.final_cost;
        best_summary = summary;
        result.robust_loss_noise_scale = scale;
        continue;
      }
    }
    break;
  }
  result.starts_run = starts;
  result.iterations = static_cast<int>(best_summary.iterations.size());

  // 4. Divergence guard: keep the nominal model when the solve failed or made the fit worse.
  Eigen::VectorXd rb;
  Eigen::MatrixXd Jb;
  std::vector<std::pair<int, int>> pose_rows;
  const bool have_best = best_usable && evaluate_all(as, best, true, rb, Jb, &pose_rows);
  if (!have_best) {
    result.status = IdentificationStatus::kDiverged;
    result.message =
        fmt::format("the solve diverged or left a pose unsolvable ({}); the nominal model is kept",
                    best_summary.message.empty() ? "no usable solution" : best_summary.message);
    result.estimate = nominal;
    result.solve_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return result;
  }
  result.final_cost = 0.5 * rb.squaredNorm();
  result.objective = best_cost;
  if (options.robust_loss == RobustLoss::kNone && prior_terms.empty() &&
      result.final_cost > result.initial_cost * (1.0 + 1e-9)) {
    result.status = IdentificationStatus::kDiverged;
    result.message =
        fmt::format("the solve increased the cost ({:.6g} -> {:.6g}); the nominal model is kept",
                    result.initial_cost, result.final_cost);
    result.estimate = nominal;
    return result;
  }
  result.estimate = best;
  result.status = best_summary.termination_type == ceres::CONVERGENCE
                      ? IdentificationStatus::kConverged
                      : IdentificationStatus::kNotConverged;
  result.message = fmt::format("{} parameters estimated from {} poses ({} equations): {}",
                               result.estimated.size(), poses_used, as.rows, best_summary.message);

  // 5. Diagnostics at the estimate.
  std::vector<PoseResidual> per_pose;
  std::size_t cost_index = 0;
  for (const auto* pose : as.poses) {
    if (pose->observations.empty()) continue;
    const auto [start_row, count] = pose_rows[cost_index++];
    PoseResidual pr;
    pr.id = pose->id;
    pr.whitened = rb.segment(start_row, count);
    FramePrediction pred;
    std::string why;
    model.predict(best, pose->actuators, slot_of[pose->id], false, pred, why);
    for (const auto& obs : pose->observations) {
      if (auto p = observed_position(obs))
        pr.position_error = std::max(pr.position_error, (pred.pose.translation() - *p).norm());
      if (const auto* po = std::get_if<PoseObservation>(&obs))
        pr.orientation_error =
            Eigen::AngleAxisd(pred.pose.linear() * po->measured_rotation.transpose()).angle();
      if (const auto* ph = std::get_if<ProbeHeightObservation>(&obs))
        pr.position_error = std::max(
            pr.position_error,
            std::abs(ph->normal.dot(pred.pose.translation()) - ph->offset - ph->measured_height));
    }
    per_pose.push_back(std::move(pr));
  }
  // Provisional flags (stated noise, robust scale): only used to leave the poses a robust loss
  // rejected out of the covariance; the final test below uses normalised residuals.
  result.residuals = diagnose_residuals(per_pose, options.outliers);

  // Covariance from the inlier rows (outliers flagged by the robust fit do not inform it).
  std::vector<Eigen::Index> keep_rows;
  std::vector<bool> pose_in_fit(pose_rows.size(), true);
  for (std::size_t k = 0; k < pose_rows.size(); ++k) {
    if (options.robust_loss != RobustLoss::kNone && result.residuals.poses[k].outlier) {
      pose_in_fit[k] = false;
      continue;
    }
    for (int i = 0; i < pose_rows[k].second; ++i) keep_rows.push_back(pose_rows[k].first + i);
  }
  for (Eigen::Index i = pose_rows.empty() ? 0 : pose_rows.back().first + pose_rows.back().second;
       i < Jb.rows(); ++i)
    keep_rows.push_back(i);
  const auto n_est = static_cast<Eigen::Index>(result.estimated.size());
  Eigen::MatrixXd Je(
      static_cast<Eigen::Index>(keep_rows.size()) + static_cast<Eigen::Index>(prior_terms.size()),
      n_est);
  Eigen::VectorXd re(Je.rows());
  std::vector<int> je_group;
  Je.setZero();
  for (std::size_t k = 0; k < keep_rows.size(); ++k) {
    for (Eigen::Index c = 0; c < n_est; ++c)
      Je(static_cast<Eigen::Index>(k), c) = Jb(
          keep_rows[k], static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)]));
    re(static_cast<Eigen::Index>(k)) = rb(keep_rows[k]);
    je_group.push_back(as.row_group[static_cast<std::size_t>(keep_rows[k])]);
  }
  for (std::size_t t = 0; t < prior_terms.size(); ++t) {
    const auto row = static_cast<Eigen::Index>(keep_rows.size() + t);
    const auto it =
        std::find(result.estimated.begin(), result.estimated.end(), prior_terms[t].first);
    Je(row, it - result.estimated.begin()) = 1.0 / prior_terms[t].second;
    re(row) = (best(static_cast<Eigen::Index>(prior_terms[t].first)) -
               nominal(static_cast<Eigen::Index>(prior_terms[t].first))) /
              prior_terms[t].second;
    je_group.push_back(-1);  // a prior is information, not noise to estimate
  }
  // A posteriori noise per observation type (noise_estimate.hpp); applied to the covariance
  // unless the stated noise is declared known.
  result.noise = estimate_noise(Je, re, je_group, as.groups);
  Eigen::VectorXd row_scale = Eigen::VectorXd::Ones(Je.rows());
  if (result.noise.ok) {
    result.noise_applied = !options.keep_stated_noise &&
                           std::any_of(result.noise.groups.begin(), result.noise.groups.end(),
                                       [](const NoiseGroup& g) { return g.estimable; });
    if (result.noise_applied) row_scale = result.noise.row_scale;
    add_noise_warnings(result.noise, result.noise_applied, result.warnings);
  }
  std::vector<std::string> est_names;
  for (std::size_t i : result.estimated) est_names.push_back(result.names[i]);
  result.uncertainty = parameter_uncertainty(row_scale.cwiseInverse().asDiagonal() * Je, est_names,
                                             options.covariance, re.cwiseQuotient(row_scale));
  if (result.noise_applied && result.uncertainty.ok) {
    // One observation type: the classical variance factor; several: per-type, see `noise`.
    int estimable = 0;
    double factor = 1.0;
    for (const auto& g : result.noise.groups)
      if (g.estimable) {
        ++estimable;
        factor = g.scale * g.scale;
      }
    if (estimable == 1) result.uncertainty.variance_factor *= factor;
  }
  // Final outlier test on normalised residuals: each pose's whitened residual divided by its
  // type's noise scale (the robust one when asked), tested against its own covariance
  // I ∓ J_b C J_bᵀ, so leverage and any mix of σ are accounted for.
  if (result.noise.ok) {
    const auto& groups = result.noise.groups;  // same order as as.groups
    auto test_scale_of = [&](const NoiseGroup& g) {
      return options.outliers.robust_scale ? g.robust_scale : result.noise_applied ? g.scale : 1.0;
    };
    // normal_inverse is in the reweighted problem's units (rows / row_scale).
    // C = S Sᵀ for the factored form (PoseResidual::leverage_factor = J_b S).
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> c_eig(result.noise.normal_inverse);
    const Eigen::MatrixXd c_root =
        c_eig.eigenvectors() * c_eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
    for (std::size_t k = 0; k < per_pose.size(); ++k) {
      const auto [start_row, count] = pose_rows[k];
      Eigen::MatrixXd Jp(count, n_est);
      Eigen::VectorXd fit_scale(count);
      Eigen::VectorXd test_scale(count);
      for (int i = 0; i < count; ++i) {
        const auto& g =
            groups[static_cast<std::size_t>(as.row_group[static_cast<std::size_t>(start_row + i)])];
        fit_scale(i) = g.scale;
        test_scale(i) = test_scale_of(g);
        for (Eigen::Index c = 0; c < n_est; ++c)
          Jp(i, c) = Jb(start_row + i,
                        static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)])) /
                     fit_scale(i);
      }
      // Residual covariance in units of the fit scale, then re-expressed in the test scale.
      const Eigen::VectorXd ratio = fit_scale.cwiseQuotient(test_scale);
      const bool one_ratio =
          count > 0 && ratio.maxCoeff() - ratio.minCoeff() <= 1e-12 * ratio.cwiseAbs().maxCoeff();
      if (one_ratio) {
        // One noise scale in the block (e.g. all pixel rows): the factored form, exact and cheap.
        per_pose[k].leverage_factor = Jp * c_root;
        per_pose[k].leverage_sign = pose_in_fit[k] ? -1.0 : 1.0;
        per_pose[k].covariance_factor = ratio(0) * ratio(0);
      } else {
        per_pose[k].residual_covariance =
            ratio.asDiagonal() *
            pose_residual_covariance(Jp, result.noise.normal_inverse, pose_in_fit[k]) *
            ratio.asDiagonal();
      }
      per_pose[k].whitened = per_pose[k].whitened.cwiseQuotient(test_scale);
    }
    result.residuals = diagnose_residuals(per_pose, options.outliers);
  }
  result.residuals.by_type =
      residuals_by_type(model, best, as.poses, slot_of, measurements.distances);
  if (result.uncertainty.ok) {
    std::vector<Eigen::MatrixXd> frame_jacobians;
    for (const auto* pose : as.poses) {
      FramePrediction pred;
      std::string why;
      if (!model.predict(best, pose->actuators, slot_of[pose->id], true, pred, why)) continue;
      Eigen::MatrixXd Js(6, n_est);
      for (Eigen::Index c = 0; c < n_est; ++c)
        Js.col(c) = pred.jacobian.col(
            static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)]));
      frame_jacobians.push_back(std::move(Js));
    }
    result.predicted = predict_accuracy(frame_jacobians, result.uncertainty.covariance);
  } else {
    result.warnings.push_back("no covariance: " + result.uncertainty.message);
  }
  {
    // Goodness of fit: ‖r‖² should be near the degrees of freedom when the model and the stated
    // noise are right. Far above it means a local minimum, a wrong model or optimistic noise.
    const double dof = std::max(1.0, static_cast<double>(as.rows) - static_cast<double>(n_est));
    const double ratio = 2.0 * result.final_cost / dof;
    if (ratio > 25.0)
      result.warnings.push_back(fmt::format(
          "the residuals are {:.3g} times larger than the stated measurement noise (reduced "
          "chi-square {:.3g}): a local minimum (try multi-start), an unmodelled error or "
          "optimistic noise",
          std::sqrt(ratio), ratio));
    if (prior_terms.empty() && static_cast<double>(as.rows) <= static_cast<double>(n_est))
      result.warnings.push_back(fmt::format(
          "no redundancy: {} equations for {} estimated parameters, so the fit passes through "
          "every measurement exactly; neither the noise nor outliers can be checked (measure a "
          "few more points)",
          as.rows, n_est));
  }
  if (result.residuals.outliers > 0)
    result.warnings.push_back(
        fmt::format("{} poses flagged as outliers", result.residuals.outliers));
  result.solve_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
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
