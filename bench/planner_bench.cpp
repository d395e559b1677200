// Planner figures, printed as JSON.
//
//   build/release/bench/robocal_planner_bench [trials] [pool] [count]
//
// Cell: testdata/cells/delta_two_cameras.yaml (rotary Delta, two cameras below, a fixture box
// intruding into the workspace). Per trial t (default 20):
//  - truth = nominal + perturbation of every free parameter (lengths σ 0.5 mm, angles σ 0.2°, as
//    identify_bench);
//  - a candidate pool of `pool` joint-space samples (default 5000, seed t) filtered by the full
//    feasibility test (reach, workspace, FCL collision, visibility in both cameras);
//  - designs of `count` poses (default 40) from the feasible pool: uniformly at random, and
//    planned by each index O1..O5 (greedy + DETMAX);
//  - each design measured on the true robot with the same noise (full pose, σ 20 µm, 1e-4 rad,
//    same noise seed per trial) and identified (robot-file free set, automatic base set);
//  - held-out error: RMS position error of the identified model against the truth over 300
//    feasible poses of another pool (noise-free).
//  - also the 'task' criterion (mean predicted position variance over the pool, I-optimal);
//  - the bound: the continuous I-optimal design over the pool (see continuous_task_bound), the
//    lowest predicted held-out RMS any `count` poses from that pool can give.
// Reported: median over trials of each design's held-out RMS, ratio planned/random per index;
// per trial the identification status with the number of estimated parameters ("est=") and
// those its relinearisation added ("relin+").
// Diagnosis: ROBOCAL_PLANNER_NOISE=0 (no noise: the model's own error), =k (k x the noise);
// ROBOCAL_PLANNER_FEASIBLE=N (pool = N feasible candidates, sampled until reached);
// ROBOCAL_PLANNER_SKIP_SPEED=1 (no speed part).
// Speed (CPU time of the one thread): a pool of 5000 FEASIBLE candidates, N = 60: Jacobian model
// build, plain greedy pass, greedy + DETMAX (O1), each timed.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/selection.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <iostream>
#include <random>
#include <string>
#include <vector>

using namespace robocal;
using namespace robocal::planner;

namespace {

// CPU time of this thread (s): "one core" even on a loaded machine (the bench is single-threaded).
double thread_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
double seconds_since(double t0) {
  return thread_seconds() - t0;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::vector<Eigen::VectorXd> feasible_readings(const FeasibilityChecker& checker,
                                               std::size_t samples, unsigned seed,
                                               FeasibilityCounts* counts) {
  std::mt19937 rng(seed);
  std::vector<Eigen::VectorXd> out;
  for (const Candidate& c : checker.sample(samples, rng, counts))
    if (c.feasible()) out.push_back(c.readings);
  return out;
}

// Held-out RMS position error (m) of the model identified from `design` measured on `truth`.
double held_out_error(const calib::MechanismPredictor& pred, const Eigen::VectorXd& nominal,
                      const Eigen::VectorXd& truth, const std::vector<Eigen::VectorXd>& design,
                      const calib::Measurements& held, unsigned noise_seed, std::string* status) {
  calib::SimulationOptions sim;
  sim.kind = calib::SimulatedObservation::kPose;
  // ROBOCAL_PLANNER_NOISE=0 separates model error from noise (diagnosis).
  const double noise =
      std::getenv("ROBOCAL_PLANNER_NOISE") ? std::stod(std::getenv("ROBOCAL_PLANNER_NOISE")) : 1.0;
  sim.position_sigma = 20e-6;  // the weights; no noise drawn when noise == 0
  sim.rotation_sigma = 1e-4;
  sim.add_noise = noise > 0;
  if (noise > 0 && noise != 1.0) {
    sim.position_sigma *= noise;
    sim.rotation_sigma *= noise;
  }
  std::mt19937 rng(noise_seed);
  const calib::Measurements meas = calib::simulate_measurements(pred, truth, design, sim, rng);
  const calib::SolveOptions opt = calib::solve_options_from_model(pred.model(), false);
  const calib::IdentificationResult res = calib::identify(pred, nominal, meas, opt);
  *status = std::string(calib::to_string(res.status)) +
            " est=" + std::to_string(res.estimated.size()) + " relin+" +
            std::to_string(res.relinearisation.accepted ? res.relinearisation.added.size() : 0);
  return calib::validate(pred, nominal, res.estimate, held.poses).after.position_rms;
}

// Lower bound of the mean predicted position variance tr(W M^-1) that any design of `count`
// poses drawn from the pool can reach. Relaxed to weights on the pool (a design of m poses is the
// weights k_i/m, and M = m * M(w)), phi(w) = tr(W M(w)^-1) is convex, so with
// d_i = tr(J_i^T J_i M^-1 W M^-1) (its negative gradient) phi* >= 2 phi(w) - max_i d_i holds at
// every w: a certified bound while the multiplicative algorithm (w_i *= sqrt(d_i / phi)) moves
// w towards the optimum. Returned as the RMS position error (m) of `count` poses.
double continuous_task_bound(const ObservabilityModel& obs, std::size_t count) {
  const std::size_t n = obs.poses();
  const auto L = static_cast<Eigen::Index>(obs.columns());
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(L, L);
  std::vector<Eigen::MatrixXd> info(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto J = obs.rows.middleRows<6>(static_cast<Eigen::Index>(6 * i));
    const auto Jp = obs.rows.middleRows<3>(static_cast<Eigen::Index>(6 * i));
    W.noalias() += Jp.transpose() * Jp;
    info[i] = J.transpose() * J;
  }
  W /= static_cast<double>(n);
  Eigen::VectorXd w = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(n), 1.0 / n);
  double lower = 0.0;
  for (int it = 0; it < 3000; ++it) {
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(L, L);
    for (std::size_t i = 0; i < n; ++i) M.noalias() += w(static_cast<Eigen::Index>(i)) * info[i];
    const Eigen::MatrixXd Minv = M.ldlt().solve(Eigen::MatrixXd::Identity(L, L));
    const Eigen::MatrixXd G = Minv * W * Minv;
    const double phi = (W * Minv).trace();
    Eigen::VectorXd d(static_cast<Eigen::Index>(n));
    for (std::size_t i = 0; i < n; ++i)
      d(static_cast<Eigen::Index>(i)) = info[i].cwiseProduct(G).sum();
    lower = std::max(lower, 2.0 * phi - d.maxCoeff());
    if (d.maxCoeff() < phi * 1.001) break;
    for (Eigen::Index i = 0; i < w.size(); ++i) w(i) *= std::sqrt(d(i) / phi);
    w /= w.sum();
  }
  return obs.position_sigma * std::sqrt(std::max(lower, 0.0) / static_cast<double>(count));
}

}  // namespace

int main(int argc, char** argv) {
  // "speed" as the first argument runs only the speed part.
  const bool speed_only = argc > 1 && std::string(argv[1]) == "speed";
  const int trials = speed_only ? 0 : argc > 1 ? std::stoi(argv[1]) : 20;
  const std::size_t pool_size = argc > 2 ? std::stoul(argv[2]) : 5000;
  const std::size_t count = argc > 3 ? std::stoul(argv[3]) : 40;
  const std::string data = ROBOCAL_TESTDATA_DIR;
  const calib::Mechanism model = calib::load_robot_file(data + "/robots/rotary_delta.yaml");
  const Cell cell = load_cell_file(data + "/cells/delta_two_cameras.yaml");
  const Eigen::VectorXd nominal = model.nominal_parameters();
  const int frame = target_frame(model, cell);
  const FeasibilityChecker checker(model, nominal, cell, frame,
                                   feasibility_options_from_cell(cell));
  const calib::MechanismPredictor pred(model, frame);
  const Eigen::VectorXd sig = calib::tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0);

  nlohmann::json out;
  out["robot"] = model.name;
  out["cell"] = cell.source;
  out["trials"] = trials;
  out["pool_samples"] = pool_size;
  out["poses"] = count;

  // Held-out poses: one fixed feasible set from a separate pool.
  FeasibilityCounts held_counts;
  std::vector<Eigen::VectorXd> held_readings =
      feasible_readings(checker, speed_only ? 0 : 12000, 999, &held_counts);
  if (held_readings.size() > 300) held_readings.resize(300);
  out["held_out_poses"] = held_readings.size();

  const std::vector<std::string> designs = {"random", "O1", "O2", "O3", "O4", "O5", "task"};
  std::map<std::string, std::vector<double>> errors;
  std::map<std::string, std::vector<double>> conds;
  std::map<std::string, std::vector<double>> predicted;
  std::map<std::string, double> select_time;
  std::vector<double> bounds;  // per trial, continuous_task_bound
  nlohmann::json per_trial = nlohmann::json::array();
  std::size_t feasible_total = 0;
  FeasibilityCounts first_counts;
  for (int t = 0; t < trials; ++t) {
    std::mt19937 rng(1000 + static_cast<unsigned>(t));
    const Eigen::VectorXd truth = calib::perturb_parameters(nominal, sig, rng);
    calib::SimulationOptions clean;
    clean.kind = calib::SimulatedObservation::kPoint;
    clean.add_noise = false;
    const calib::Measurements held =
        calib::simulate_measurements(pred, truth, held_readings, clean, rng);
    FeasibilityCounts counts;
    std::vector<Eigen::VectorXd> pool =
        feasible_readings(checker, pool_size, 1 + static_cast<unsigned>(t), &counts);
    if (const char* f = std::getenv("ROBOCAL_PLANNER_FEASIBLE")) {
      const std::size_t want = std::stoul(f);
      unsigned s2 = 100000 + 1000 * static_cast<unsigned>(t);
      while (pool.size() < want) {
        const auto more = feasible_readings(checker, pool_size, s2++, &counts);
        pool.insert(pool.end(), more.begin(), more.end());
      }
      pool.resize(want);
    }
    if (t == 0) first_counts = counts;
    feasible_total += pool.size();
    const ObservabilityModel obs = build_observability_model(pred, nominal, pool);
    nlohmann::json row;
    bounds.push_back(continuous_task_bound(obs, count));
    row["bound_rms_um"] = 1e6 * bounds.back();
    row["trial"] = t;
    row["feasible"] = pool.size();
    for (const std::string& d : designs) {
      std::vector<std::size_t> chosen;
      if (d == "random") {
        std::vector<std::size_t> idx(pool.size());
        for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
        std::shuffle(idx.begin(), idx.end(), rng);
        chosen.assign(idx.begin(),
                      idx.begin() + static_cast<std::ptrdiff_t>(std::min(count, idx.size())));
      } else {
        SelectionOptions so;
        parse_index(d, &so.index);
        so.count = count;
        const auto t0 = thread_seconds();
        chosen = select_poses(obs, so).chosen;
        select_time[d] += seconds_since(t0);
      }
      std::vector<Eigen::VectorXd> design;
      for (const std::size_t i : chosen) design.push_back(pool[i]);
      std::string status;
      const double e = held_out_error(pred, nominal, truth, design, held,
                                      5000 + static_cast<unsigned>(t), &status);
      errors[d].push_back(e);
      conds[d].push_back(evaluate_set(obs, chosen).condition_number);
      double pred_rms = 0.0, pred_max = 0.0;
      predicted_accuracy(obs, chosen, &pred_rms, &pred_max);
      predicted[d].push_back(pred_rms);
      row[d] = {{"held_out_rms_um", e * 1e6},
                {"status", status},
                {"condition", conds[d].back()},
                {"predicted_rms_um", pred_rms * 1e6}};
    }
    per_trial.push_back(row);
    std::cerr << "trial " << t << ": feasible " << pool.size() << ", random "
              << errors["random"].back() * 1e6 << " um, O1 " << errors["O1"].back() * 1e6
              << " um\n";
  }
  out["feasibility_first_trial"] = first_counts.summary();
  out["feasible_mean"] = static_cast<double>(feasible_total) / std::max(trials, 1);
  nlohmann::json summary;
  const double random_median = median(errors["random"]);
  std::string best;
  double best_err = 1e300;
  for (const std::string& d : designs) {
    const double m = median(errors[d]);
    summary[d] = {{"median_held_out_rms_um", m * 1e6},
                  {"ratio_to_random", random_median > 0 ? m / random_median : 0.0},
                  {"median_condition", median(conds[d])},
                  {"median_predicted_rms_um", median(predicted[d]) * 1e6}};
    if (d != "random") summary[d]["mean_select_seconds"] = select_time[d] / std::max(trials, 1);
    if (d != "random" && m < best_err) {
      best_err = m;
      best = d;
    }
  }
  if (!speed_only) {
    // What no design of `count` poses from the pool can beat (predicted): the ratio the planned
    // designs could reach at best against the random ones' median held-out error.
    out["bound"] = {{"median_rms_um", median(bounds) * 1e6},
                    {"ratio_to_random", random_median > 0 ? median(bounds) / random_median : 0.0}};
    out["comparison"] = summary;
    out["best_index"] = best;
    out["per_trial"] = per_trial;
  }

  // Speed: 5000 feasible candidates, N = 60, one core.
  if (std::getenv("ROBOCAL_PLANNER_SKIP_SPEED") == nullptr) {
    std::vector<Eigen::VectorXd> big;
    FeasibilityCounts counts;
    const auto t0 = thread_seconds();
    unsigned seed = 77;
    while (big.size() < 5000) {
      const std::vector<Eigen::VectorXd> more = feasible_readings(checker, 20000, seed++, &counts);
      big.insert(big.end(), more.begin(), more.end());
    }
    big.resize(5000);
    const double feas_s = seconds_since(t0);
    auto t1 = thread_seconds();
    const ObservabilityModel obs = build_observability_model(pred, nominal, big);
    const double build_s = seconds_since(t1);
    SelectionOptions so;
    so.count = 60;
    so.exchange = false;
    t1 = thread_seconds();
    const Selection greedy = select_poses(obs, so);
    const double greedy_s = seconds_since(t1);
    so.exchange = true;
    t1 = thread_seconds();
    const Selection full = select_poses(obs, so);
    const double full_s = seconds_since(t1);
    SelectionOptions o5 = so;
    o5.index = ObservabilityIndex::kO5;
    t1 = thread_seconds();
    const Selection full5 = select_poses(obs, o5);
    const double full5_s = seconds_since(t1);
    SelectionOptions ot = so;
    ot.index = ObservabilityIndex::kTask;
    t1 = thread_seconds();
    const Selection full_task = select_poses(obs, ot);
    const double full_task_s = seconds_since(t1);
    out["speed"] = {
        {"task_greedy_exchange_seconds", full_task_s},
        {"task_selection_total_seconds", build_s + full_task_s},
        {"task_exchanges", full_task.exchanges},
        {"pool", big.size()},
        {"count", 60},
        {"identifiable_parameters", obs.columns()},
        {"feasibility_seconds", feas_s},
        {"feasibility_candidates_evaluated", counts.evaluated},
        {"feasibility_us_per_candidate", 1e6 * feas_s / static_cast<double>(counts.evaluated)},
        {"jacobian_model_seconds", build_s},
        {"greedy_seconds", greedy_s},
        {"greedy_detmax_seconds", full_s},
        {"selection_total_seconds", build_s + full_s},
        {"O5_greedy_exchange_seconds", full5_s},
        {"O5_selection_total_seconds", build_s + full5_s},
        {"O5_exchanges", full5.exchanges},
        {"greedy_O1", greedy.values.o[0]},
        {"greedy_detmax_O1", full.values.o[0]},
        {"detmax_exchanges", full.exchanges},
        {"greedy_condition", greedy.values.condition_number},
        {"greedy_detmax_condition", full.values.condition_number}};
  }
  std::cout << out.dump(2) << "\n";
  return 0;
}
