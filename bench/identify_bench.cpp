// Identification figures, printed as JSON.
//
//   build/release/bench/robocal_identify_bench [robot.yaml] [draws] [identifiable|all|groups|rank]
//
// For the robot (default: testdata/robots/rotary_delta.yaml):
//  - truth = nominal + perturbation of every free parameter (lengths σ 0.5 mm, angles σ 0.2°;
//    on the Delta the shoulders' a3 are the encoder zero offsets, so they get σ 0.2° too);
//  - 60 design poses (uniform in the actuator limits), 3-D point observations with σ 20 µm,
//    no priors; identifiable set chosen automatically at the nominal model;
//  - calibrated-model position error vs truth, RMS over 500 held-out poses, for ≥ 20 noise
//    draws: mean-square average, spread, and the Cramér–Rao prediction from the design's
//    Fisher information at the truth (J_h (JᵀJ)⁻¹ J_hᵀ over the held-out poses) over each draw's
//    own estimated set (the relinearised second solve may add parameters; mean square over draws);
//  - the same with only base + tool frames fitted (what hand–eye alone gives) and raw nominal;
//  - noise-free recovery (max held-out error);
//  - time of a full-pose identification with 125 and 500 poses (one core).
// Diagnosis modes: "groups" = noise-free recovery with one body's lengths (then angles) perturbed
// at a time (fit RMS, held-out median/p90/max, parameters moved); "rank" = rank and singular values
// of the scaled identification Jacobian at nominal and at the all-perturbed truth. Environment
// ROBOCAL_NOMINAL_BODIES=body6,body9 keeps those bodies nominal in the truth.
// With a working volume (robot file `workspace:` or ROBOCAL_MIN_TASK_CONDITIONING=X) the figures
// are printed twice: design and held-out poses inside it ("working_volume") and over the full
// reachable set; each with the held-out error binned by the pose's task conditioning
// (σ_min/σ_max of d(position)/d(actuators)) and by the closure's, and the five worst poses.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <iostream>
#include <map>
#include <string>

using namespace robocal::calib;

namespace {

struct HeldOut {
  std::vector<Eigen::VectorXd> readings;
  std::vector<Eigen::Vector3d> truth;
};

double heldout_rms(const MechanismPredictor& pred, const Eigen::VectorXd& params, const HeldOut& h,
                   double* max_err = nullptr, double* median_err = nullptr,
                   std::vector<double>* per_pose = nullptr) {
  double sum = 0.0;
  double worst = 0.0;
  std::vector<double> errors;
  for (std::size_t k = 0; k < h.readings.size(); ++k) {
    FramePrediction fp;
    std::string why;
    if (!pred.predict(params, h.readings[k], static_cast<int>(100000 + k), false, fp, why))
      return INFINITY;
    const double e = (fp.pose.translation() - h.truth[k]).norm();
    sum += e * e;
    worst = std::max(worst, e);
    errors.push_back(e);
  }
  if (per_pose) *per_pose = errors;
  if (max_err) *max_err = worst;
  if (median_err && !errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + static_cast<long>(errors.size() / 2),
                     errors.end());
    *median_err = errors[errors.size() / 2];
  }
  return std::sqrt(sum / static_cast<double>(h.readings.size()));
}

// Held-out error against the pose's conditioning (σ_min/σ_max of the task Jacobian at the truth).
const std::vector<double> kConditioningEdges = {0.0, 0.03, 0.1, 0.2, 0.3, 0.5, 1.01};

// Same against σ_min/σ_max of the closure's constraint Jacobian (the sampler admits ≥ 0.01).
const std::vector<double> kClosureEdges = {0.0, 0.02, 0.05, 0.1, 0.2, 1.01};

nlohmann::json by_conditioning(const std::vector<double>& conditioning,
                               const std::vector<std::vector<double>>& errors_per_draw,
                               const std::vector<double>& edges = kConditioningEdges) {
  nlohmann::json rows;
  for (std::size_t b = 0; b + 1 < edges.size(); ++b) {
    double sum = 0.0;
    double worst = 0.0;
    std::size_t n = 0;
    std::size_t poses = 0;
    for (std::size_t k = 0; k < conditioning.size(); ++k) {
      if (conditioning[k] < edges[b] || conditioning[k] >= edges[b + 1]) continue;
      ++poses;
      for (const auto& e : errors_per_draw) {
        sum += e[k] * e[k];
        worst = std::max(worst, e[k]);
        ++n;
      }
    }
    rows.push_back({{"conditioning", {edges[b], edges[b + 1]}},
                    {"poses", poses},
                    {"rms_m", n ? std::sqrt(sum / static_cast<double>(n)) : NAN},
                    {"max_m", worst}});
  }
  return rows;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string path =
      argc > 1 ? argv[1] : std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml";
  const int draws = argc > 2 ? std::stoi(argv[2]) : 20;
  Mechanism model = load_robot_file(path);
  // Experiment: ROBOCAL_MIN_TASK_CONDITIONING=X acts as `workspace: {min_task_conditioning: X}`.
  if (const char* c = std::getenv("ROBOCAL_MIN_TASK_CONDITIONING"))
    model.workspace.min_task_conditioning = std::stod(c);
  const MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  // ROBOCAL_BENCH_SEED=N draws another truth and design (the figures in the README use the
  // default).
  std::mt19937 rng(std::getenv("ROBOCAL_BENCH_SEED")
                       ? static_cast<unsigned>(std::stoul(std::getenv("ROBOCAL_BENCH_SEED")))
                       : 20261122u);
  const Eigen::VectorXd sig = tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0);
  Eigen::VectorXd truth = perturb_parameters(nominal, sig, rng);

  Eigen::VectorXd truth_all = truth;
  auto design = sample_actuators(pred, {nominal, truth_all}, 60, rng, 0.01, false);
  // Scenario "identifiable" (default): the truth differs from nominal in the identifiable base
  // set only (the redundant parameters' true deviations are absorbed into it, exactly as a real
  // calibration reports them). Scenario "all": every free parameter perturbed; redundancies
  // found at the nominal model are then only first-order and leave a model error.
  const bool perturb_all = argc > 3 && std::string(argv[3]) == "all";
  {
    SimulationOptions clean;
    clean.add_noise = false;
    const auto meas = simulate_measurements(pred, nominal, design, clean, rng);
    const auto base = identify(pred, nominal, meas, solve_options_from_model(model, false));
    if (const char* keep = std::getenv("ROBOCAL_NOMINAL_BODIES")) {
      // Experiment: these bodies (comma list of names) keep their nominal geometry in the truth.
      const std::string list = std::string(",") + keep + ",";
      for (std::size_t i = 0; i < model.parameters.size(); ++i) {
        const Parameter& p = model.parameters[i];
        if (p.body >= 0 && list.find("," + model.bodies[static_cast<std::size_t>(p.body)].name +
                                     ",") != std::string::npos)
          truth(static_cast<Eigen::Index>(i)) = nominal(static_cast<Eigen::Index>(i));
      }
    }
    if (!perturb_all) {
      truth = nominal;
      for (std::size_t i : base.estimated)
        truth(static_cast<Eigen::Index>(i)) = truth_all(static_cast<Eigen::Index>(i));
    }
  }
  HeldOut held;
  held.readings = sample_actuators(pred, {nominal, truth}, 500, rng, 0.01, false);
  for (std::size_t k = 0; k < held.readings.size(); ++k) {
    FramePrediction fp;
    std::string why;
    pred.predict(truth, held.readings[k], -1, false, fp, why);
    held.truth.push_back(fp.pose.translation());
  }
  if (argc > 3 && std::string(argv[3]) == "rank") {
    // Rank of the scaled identification Jacobian over the free parameters at nominal and truth.
    const SolveOptions o = solve_options_from_model(model, false);
    for (const Eigen::VectorXd* at : std::vector<const Eigen::VectorXd*>{&nominal, &truth_all}) {
      Eigen::MatrixXd J(3 * static_cast<Eigen::Index>(design.size()),
                        static_cast<Eigen::Index>(o.candidates.size()));
      for (std::size_t k = 0; k < design.size(); ++k) {
        FramePrediction fp;
        std::string why;
        pred.predict(*at, design[k], -1, true, fp, why);
        for (std::size_t c = 0; c < o.candidates.size(); ++c)
          J.block(3 * static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(c), 3, 1) =
              fp.jacobian.col(static_cast<Eigen::Index>(o.candidates[c])).head<3>();
      }
      std::vector<std::string> names;
      std::vector<int> pref;
      for (std::size_t c : o.candidates) {
        names.push_back(model.parameters[c].name);
        pref.push_back(o.preference[c]);
      }
      const auto rep = analyze_identifiability(J, names, o.identifiability, pref);
      std::cout << "rank " << rep.rank << " sv:";
      for (Eigen::Index i = 0; i < rep.singular_values.size() && i < 80; ++i)
        std::cout << " " << rep.singular_values(i) / rep.singular_values(0);
      std::cout << "\nbase:";
      for (std::size_t k : rep.identifiable) std::cout << " " << names[k];
      std::cout << "\n";
    }
    return 0;
  }
  if (argc > 3 && std::string(argv[3]) == "groups") {
    // Noise-free diagnosis: perturb one body's parameters (lengths, then angles) at a time.
    nlohmann::json rows;
    const auto held_pool = sample_actuators(pred, {nominal}, 200, rng);
    SimulationOptions clean;
    clean.add_noise = false;
    const SolveOptions o = solve_options_from_model(model, false);
    for (std::size_t b = 0; b < model.bodies.size(); ++b) {
      for (int kind = 0; kind < 2; ++kind) {
        Eigen::VectorXd t = nominal;
        std::string names;
        for (std::size_t i = 0; i < model.parameters.size(); ++i) {
          const Parameter& p = model.parameters[i];
          if (p.body != static_cast<int>(b) || !p.free) continue;
          if ((p.unit == ParamUnit::kAngle) != (kind == 1)) continue;
          t(static_cast<Eigen::Index>(i)) = truth_all(static_cast<Eigen::Index>(i));
          names += p.name + " ";
        }
        if (names.empty()) continue;
        const auto meas = simulate_measurements(pred, t, design, clean, rng);
        const auto res = identify(pred, nominal, meas, o);
        HeldOut h;
        h.readings = held_pool;
        for (const auto& r : h.readings) {
          FramePrediction fp;
          std::string why;
          pred.predict(t, r, -1, false, fp, why);
          h.truth.push_back(fp.pose.translation());
        }
        double worst = 0.0;
        const double hr = heldout_rms(pred, res.estimate, h, &worst);
        std::vector<double> errs;
        for (std::size_t k = 0; k < h.readings.size(); ++k) {
          HeldOut one;
          one.readings = {h.readings[k]};
          one.truth = {h.truth[k]};
          errs.push_back(heldout_rms(pred, res.estimate, one));
        }
        std::sort(errs.begin(), errs.end());
        nlohmann::json moved;
        for (std::size_t i : res.estimated) {
          const auto ii = static_cast<Eigen::Index>(i);
          if (std::abs(res.estimate(ii) - t(ii)) > 1e-7)
            moved[model.parameters[i].name] = {res.estimate(ii) - nominal(ii), t(ii) - nominal(ii)};
        }
        rows.push_back({{"params", names},
                        {"fit_rms_m", res.residuals.position_rms},
                        {"iterations", res.iterations},
                        {"status", to_string(res.status)},
                        {"heldout_max_m", worst},
                        {"heldout_median_m", errs[errs.size() / 2]},
                        {"heldout_p90_m", errs[errs.size() * 9 / 10]},
                        {"moved", moved},
                        {"heldout_rms_m", hr}});
      }
    }
    std::cout << rows.dump(1) << std::endl;
    return 0;
  }
  nlohmann::json out;
  out["robot"] = model.name;
  out["workspace_min_task_conditioning"] = model.workspace.min_task_conditioning;
  // Figures over the robot file's working volume (design AND held-out poses sampled inside it),
  // and over the full reachable set (σ_min/σ_max of the closure Jacobian ≥ 0.01 only).
  const auto full_design = design;
  const auto full_held = held.readings;
  for (const bool inside : {false, true}) {
    if (!inside || model.workspace.min_task_conditioning > 0.0) {
      // The full reachable set reuses the poses drawn above (the identifiable truth is defined
      // on that design); the working volume draws its own inside it.
      design = full_design;
      held = HeldOut{};
      held.readings = full_held;
      if (inside) {
        design = sample_actuators(pred, {nominal, truth_all}, 60, rng);
        held.readings = sample_actuators(pred, {nominal, truth}, 500, rng);
      }
      std::vector<double> conditioning;
      std::vector<double> closure_conditioning;
      for (const auto& r : held.readings) {
        FramePrediction fp;
        std::string why;
        pred.predict(truth, r, -1, false, fp, why);
        held.truth.push_back(fp.pose.translation());
        conditioning.push_back(task_conditioning(pred, truth, r));
        ClosureOptions diag;
        diag.diagnose = true;
        const ClosureResult c = solve_closure(model, truth, r, {}, diag);
        closure_conditioning.push_back(c.sigma_max > 0.0 ? c.sigma_min / c.sigma_max : 0.0);
      }
      nlohmann::json& region = out[inside ? "working_volume" : "full_reachable_set"];
      region["truth"] =
          perturb_all ? "all free parameters perturbed" : "identifiable base set perturbed";
      region["parameters"] = model.parameters.size();
      region["design_poses"] = design.size();
      region["heldout_poses"] = held.readings.size();
      {
        std::vector<double> sorted = conditioning;
        std::sort(sorted.begin(), sorted.end());
        if (!sorted.empty())
          region["heldout_conditioning_min_median"] = {sorted.front(), sorted[sorted.size() / 2]};
      }

      const double sigma = 20e-6;
      SolveOptions opt = solve_options_from_model(model, false);

      // Noise-free recovery.
      {
        SimulationOptions sim;
        sim.add_noise = false;
        const auto meas = simulate_measurements(pred, truth, design, sim, rng);
        const auto res = identify(pred, nominal, meas, opt);
        double worst = 0.0;
        double median = 0.0;
        std::vector<double> per_pose;
        const double rms = heldout_rms(pred, res.estimate, held, &worst, &median, &per_pose);
        region["noise_free_by_conditioning"] = by_conditioning(conditioning, {per_pose});
        // The five worst held-out poses: conditioning and the plate ball joint's (3R) angles.
        std::vector<std::size_t> order(per_pose.size());
        for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
        std::sort(order.begin(), order.end(),
                  [&](std::size_t a, std::size_t b) { return per_pose[a] > per_pose[b]; });
        for (std::size_t w = 0; w < std::min<std::size_t>(5, order.size()); ++w) {
          const std::size_t k = order[w];
          const ClosureResult c = solve_closure(model, truth, held.readings[k]);
          nlohmann::json joints;
          for (std::size_t j = 0; j < model.passive.size(); ++j) {
            const std::string& name = model.bodies[static_cast<std::size_t>(model.passive[j])].name;
            if (name == "body7" || name == "body8" || name == "body9")
              joints[name] = c.passive(static_cast<Eigen::Index>(j));
          }
          region["noise_free_worst_poses"].push_back(
              {{"error_m", per_pose[k]},
               {"task_conditioning", conditioning[k]},
               {"readings", std::vector<double>(held.readings[k].data(),
                                                held.readings[k].data() + held.readings[k].size())},
               {"ball_joint_3r", joints}});
        }
        region["noise_free_by_closure_conditioning"] =
            by_conditioning(closure_conditioning, {per_pose}, kClosureEdges);
        region["noise_free"] = {{"status", to_string(res.status)},
                                {"estimated", res.estimated.size()},
                                {"heldout_rms_m", rms},
                                {"heldout_median_m", median},
                                {"heldout_max_m", worst},
                                {"identify_seconds", res.solve_seconds}};
      }

      // Noisy draws.
      std::vector<double> rms_draws;
      std::vector<double> median_draws;
      std::vector<double> base_tool_draws;
      std::vector<std::vector<double>> per_pose_draws;
      std::vector<std::size_t> estimated;
      // Each draw's estimated set (the relinearised solve may add parameters in some draws only):
      // the Cramér–Rao figure is the mean square over the draws' own sets.
      std::vector<std::vector<std::size_t>> draw_sets;
      int relinearised = 0;
      double seconds = 0.0;
      int failures = 0;
      SimulationOptions sim;
      sim.position_sigma = sigma;
      SolveOptions frames_only = opt;
      frames_only.candidates.clear();
      {
        std::vector<bool> tool_chain(model.bodies.size(), false);
        for (int b = model.tool;
             b >= 0 && model.bodies[static_cast<std::size_t>(b)].joint == JointType::kFixed;
             b = model.bodies[static_cast<std::size_t>(b)].parent)
          tool_chain[static_cast<std::size_t>(b)] = true;
        for (std::size_t i = 0; i < model.parameters.size(); ++i) {
          const Parameter& p = model.parameters[i];
          if (!p.free || p.group != ParamGroup::kFrame || p.body < 0) continue;
          const Body& b = model.bodies[static_cast<std::size_t>(p.body)];
          if (b.parent < 0 || tool_chain[static_cast<std::size_t>(p.body)])
            frames_only.candidates.push_back(i);
        }
      }
      for (int d = 0; d < draws; ++d) {
        const auto meas = simulate_measurements(pred, truth, design, sim, rng);
        const auto res = identify(pred, nominal, meas, opt);
        seconds += res.solve_seconds;
        if (res.status != IdentificationStatus::kConverged &&
            res.status != IdentificationStatus::kNotConverged) {
          ++failures;
          continue;
        }
        if (estimated.empty()) estimated = res.estimated;
        draw_sets.push_back(res.estimated);
        if (res.relinearisation.accepted) ++relinearised;
        double median = 0.0;
        per_pose_draws.emplace_back();
        rms_draws.push_back(
            heldout_rms(pred, res.estimate, held, nullptr, &median, &per_pose_draws.back()));
        median_draws.push_back(median);
        const auto bt = identify(pred, nominal, meas, frames_only);
        base_tool_draws.push_back(heldout_rms(pred, bt.estimate, held));
      }
      auto mean_square_root = [](const std::vector<double>& v) {
        double s = 0.0;
        for (double x : v) s += x * x;
        return v.empty() ? NAN : std::sqrt(s / static_cast<double>(v.size()));
      };
      auto stddev = [](const std::vector<double>& v) {
        double m = 0.0;
        for (double x : v) m += x;
        m /= static_cast<double>(v.size());
        double s = 0.0;
        for (double x : v) s += (x - m) * (x - m);
        return std::sqrt(s / static_cast<double>(v.size() > 1 ? v.size() - 1 : 1));
      };

      // Cramér–Rao: Fisher information of the design at the truth over a parameter set (the
      // estimator's own set; and, for reference, the base set chosen AT the truth, i.e. what an
      // estimator that could represent this truth exactly would have to estimate).
      auto cramer_rao_over = [&](const std::vector<std::size_t>& set) -> double {
        if (set.empty()) return NAN;
        const auto n = static_cast<Eigen::Index>(set.size());
        Eigen::MatrixXd J(3 * static_cast<Eigen::Index>(design.size()), n);
        for (std::size_t k = 0; k < design.size(); ++k) {
          FramePrediction fp;
          std::string why;
          pred.predict(truth, design[k], -1, true, fp, why);
          for (Eigen::Index c = 0; c < n; ++c)
            J.block(3 * static_cast<Eigen::Index>(k), c, 3, 1) =
                fp.jacobian.col(static_cast<Eigen::Index>(set[static_cast<std::size_t>(c)]))
                    .head<3>() /
                sigma;
        }
        std::vector<std::string> names(set.size(), "p");
        const auto u = parameter_uncertainty(J, names);
        if (!u.ok) {
          std::cerr << "Cramér–Rao over " << set.size() << " parameters: " << u.message << "\n";
          return NAN;
        }
        std::vector<Eigen::MatrixXd> hj;
        for (const auto& r : held.readings) {
          FramePrediction fp;
          std::string why;
          pred.predict(truth, r, -1, true, fp, why);
          Eigen::MatrixXd Jh(3, n);
          for (Eigen::Index c = 0; c < n; ++c)
            Jh.col(c) = fp.jacobian.col(static_cast<Eigen::Index>(set[static_cast<std::size_t>(c)]))
                            .head<3>();
          hj.push_back(Jh);
        }
        return predict_accuracy(hj, u.covariance).position_rms_overall;
      };
      const double cramer_rao = cramer_rao_over(estimated);
      std::vector<std::size_t> truth_base;
      {
        Eigen::MatrixXd J(3 * static_cast<Eigen::Index>(design.size()),
                          static_cast<Eigen::Index>(opt.candidates.size()));
        for (std::size_t k = 0; k < design.size(); ++k) {
          FramePrediction fp;
          std::string why;
          pred.predict(truth, design[k], -1, true, fp, why);
          for (std::size_t c = 0; c < opt.candidates.size(); ++c)
            J.block(3 * static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(c), 3, 1) =
                fp.jacobian.col(static_cast<Eigen::Index>(opt.candidates[c])).head<3>() / sigma;
        }
        std::vector<std::string> names;
        std::vector<int> pref;
        for (std::size_t c : opt.candidates) {
          names.push_back(model.parameters[c].name);
          pref.push_back(opt.preference[c]);
        }
        for (std::size_t k :
             analyze_identifiability(J, names, opt.identifiability, pref).identifiable)
          truth_base.push_back(opt.candidates[k]);
      }
      const double calibrated = mean_square_root(rms_draws);
      std::map<std::vector<std::size_t>, double> cramer_rao_of_set;
      std::vector<double> cramer_rao_draws;
      std::size_t fewest = draw_sets.empty() ? 0 : draw_sets.front().size();
      std::size_t most = fewest;
      for (const auto& set : draw_sets) {
        auto it = cramer_rao_of_set.find(set);
        if (it == cramer_rao_of_set.end())
          it = cramer_rao_of_set.emplace(set, cramer_rao_over(set)).first;
        cramer_rao_draws.push_back(it->second);
        fewest = std::min(fewest, set.size());
        most = std::max(most, set.size());
      }
      const double cramer_rao_mean = mean_square_root(cramer_rao_draws);
      region["noisy_by_conditioning"] = by_conditioning(conditioning, per_pose_draws);
      region["noisy_by_closure_conditioning"] =
          by_conditioning(closure_conditioning, per_pose_draws, kClosureEdges);
      region["noisy"] = {
          {"point_sigma_m", sigma},
          {"draws", rms_draws.size()},
          {"failed_draws", failures},
          {"estimated_parameters_min_max", {fewest, most}},
          {"relinearised_draws", relinearised},
          {"cramer_rao_first_set_rms_m", cramer_rao},
          {"calibrated_heldout_rms_m", calibrated},
          {"calibrated_heldout_rms_spread_m", rms_draws.empty() ? NAN : stddev(rms_draws)},
          {"calibrated_heldout_median_error_m", mean_square_root(median_draws)},
          {"cramer_rao_rms_m", cramer_rao_mean},
          {"rank_at_truth", truth_base.size()},
          {"cramer_rao_over_base_set_at_truth_rms_m", cramer_rao_over(truth_base)},
          {"ratio_to_cramer_rao", calibrated / cramer_rao_mean},
          {"base_tool_only_heldout_rms_m", mean_square_root(base_tool_draws)},
          {"raw_nominal_heldout_rms_m", heldout_rms(pred, nominal, held)},
          {"mean_identify_seconds",
           rms_draws.empty() ? NAN : seconds / static_cast<double>(draws)}};
    }
  }

  // Speed: full-pose observations, 125 and 500 poses.
  const double sigma = 20e-6;
  const SolveOptions opt = solve_options_from_model(model, false);
  for (std::size_t count : {std::size_t{125}, std::size_t{500}}) {
    const auto qs = sample_actuators(pred, {nominal, truth}, count, rng);
    SimulationOptions ps;
    ps.kind = SimulatedObservation::kPose;
    ps.position_sigma = sigma;
    ps.rotation_sigma = 1e-4;
    const auto meas = simulate_measurements(pred, truth, qs, ps, rng);
    const MechanismPredictor fresh(model);  // no warm starts carried over from other runs
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    const auto res = identify(fresh, nominal, meas, opt);
    const double cpu = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out["speed_full_pose"].push_back({{"poses", meas.poses.size()},
                                      {"wall_seconds", t},
                                      {"cpu_seconds", cpu},
                                      {"status", to_string(res.status)},
                                      {"iterations", res.iterations},
                                      {"estimated", res.estimated.size()},
                                      {"heldout_rms_m", heldout_rms(pred, res.estimate, held)}});
  }
  std::cout << out.dump(2) << std::endl;
  return 0;
}
