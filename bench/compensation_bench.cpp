// Compensation figures on a simulated session (e.g. `robocal demo --out DIR`),
// printed as JSON:
//
//   build/release/bench/robocal_compensation_bench SESSION [held_out]
//   build/release/bench/robocal_compensation_bench --printer
//
// - held-out targets: the configurations `robocal validate` samples (same seed, same count, same
//   models that must assemble), their TRUE tool positions taken as targets (camera 0's frame, as
//   validate reports);
// - each target compensated with the session's calibrated model (calib::compensate_target:
//   calibrated IK, then the nominal model's FK = the command for a nominal controller; the
//   nominal controller is the nominal model with its base frame fitted, identification.json
//   `start`), the command executed by the nominal controller (its IK) on the TRUE robot;
// - tool error against the target, RMS / max, next to the calibrated model's own held-out error
//   at the same configurations (what validate reports) and the uncompensated nominal controller;
// - time per target of the calibrated IK (cold: closed-form seed; warm: the previous target's
//   answer as seed), on one core; in the robot file's frame as `robocal compensate` solves it:
//   cold, warm from the previous held-out target, seeded from the nearest target already solved
//   (compensate_targets), along a path of targets 0.5 mm apart, and the whole compensate_targets
//   (IK + the nominal model's FK) per target; the same compensation per target (IK + nominal FK)
//   by the reusable calib::Compensator (and its calibrated IK alone, Compensator::calibrated_ik)
//   and by the general solvers (solve_ik + forward_kinematics,
//   the implementation before it), cold and warm from the previous target, with the
//   compensator's fallbacks to the general solvers and its agreement with them (verdicts,
//   commands, calibrated FK of its readings against the target). Times are this thread's CPU
//   time.
// --printer: the library linear delta with its printer parameters perturbed (σ 0.3 mm, as the
// printer tests), a 2006-move spiral program (5 layers, 2 mm moves) rewritten at 10 µm: time per
// move, and the calibrated IK per point along it.
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/compensation.hpp"
#include "robocal/calib/gcode_program.hpp"
#include "robocal/calib/held_out_errors.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <ctime>
#include <iostream>
#include <limits>
#include <random>
#include <string>

using namespace robocal;

namespace {

nlohmann::json stats_json(const calib::PositionErrorStats& s) {
  return {{"rms_um", s.rms * 1e6}, {"max_um", s.max * 1e6}, {"poses", s.n}};
}

// CPU time of this thread (s): the machine is shared, and wall time would count other processes
// (Google Benchmark's "CPU" column, as bench_kinematics reports).
double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double seconds_since(double t0) {
  return thread_cpu_seconds() - t0;
}

int printer_bench() {
  const calib::Mechanism m =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  Eigen::VectorXd calibrated = m.nominal_parameters();
  std::mt19937 rng(4);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (const char* name :
       {"carriage_a.encoder_offset", "carriage_b.encoder_offset", "carriage_c.encoder_offset",
        "rod_a.length", "rod_b.length", "rod_c.length", "tower_a.x", "tower_b.x", "tower_c.y"})
    calibrated[m.parameter_index(name)] += 0.3e-3 * n01(rng);
  std::string program = "G21\nG90\nM83\nG1 X0 Y0 Z1 F3000\n";
  std::vector<calib::TaskTarget> points;
  for (int layer = 0; layer < 5; ++layer) {
    for (int k = 0; k < 400; ++k) {
      const double a = k * 2.0 * M_PI / 100.0;
      const double r = 5.0 + 50.0 * k / 400.0;
      const Eigen::Vector3d p(r * std::cos(a), r * std::sin(a), 1.0 + 0.2 * layer);
      program += fmt::format("G1 X{:.3f} Y{:.3f} Z{:.3f} E0.05\n", p.x(), p.y(), p.z());
      calib::TaskTarget t;
      t.pose.translation() = p * 1e-3;
      points.push_back(t);
    }
    program += fmt::format("G0 X0 Y0 Z{:.3f}\n", 1.2 + 0.2 * layer);
  }
  const calib::CompensationModels models{&m, m.nominal_parameters(), calibrated};
  double t0 = thread_cpu_seconds();
  const auto rewrite = calib::rewrite_gcode(calib::parse_gcode(program, "spiral.gcode"), models);
  const double rewrite_s = seconds_since(t0);
  calib::IkOptions options;
  options.respect_limits = true;
  calib::IkSeed previous;
  int converged = 0;
  t0 = thread_cpu_seconds();
  for (const auto& t : points) {
    const calib::IkResult r = calib::solve_ik(m, calibrated, t, previous, options);
    if (r.ok()) {
      ++converged;
      previous = {r.actuator_q, r.passive};
    }
  }
  const double path_s = seconds_since(t0);
  int cold_converged = 0;
  t0 = thread_cpu_seconds();
  for (const auto& t : points)
    cold_converged += calib::solve_ik(m, calibrated, t, {}, options).ok() ? 1 : 0;
  const double cold_s = seconds_since(t0);
  const double np = static_cast<double>(points.size());
  const nlohmann::json out = {{"robot", m.name},
                              {"moves", rewrite.stats.moves},
                              {"emitted_moves", rewrite.stats.emitted_moves},
                              {"rewrite_s", rewrite_s},
                              {"rewrite_us_per_move", rewrite_s / rewrite.stats.moves * 1e6},
                              {"max_correction_um", rewrite.stats.max_correction * 1e6},
                              {"max_predicted_deviation_um", rewrite.stats.max_deviation * 1e6},
                              {"calibrated_ik_path_us_per_point", path_s / np * 1e6},
                              {"calibrated_ik_path_converged", converged},
                              {"calibrated_ik_cold_us_per_point", cold_s / np * 1e6},
                              {"calibrated_ik_cold_converged", cold_converged},
                              {"points", points.size()}};
  std::cout << out.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: robocal_compensation_bench SESSION [held_out] | --printer\n";
    return 2;
  }
  if (std::string(argv[1]) == "--printer") return printer_bench();
  const std::filesystem::path dir = argv[1];
  const int held_out = argc > 2 ? std::stoi(argv[2]) : 500;
  const app::Session s = app::load_session(dir);
  const app::SessionRobot robot = app::session_robot(s, "");
  // Targets are positions of the measured frame (the board's origin), as validate reports.
  calib::Mechanism model = robot.model;
  model.task.type = calib::TaskType::kPosition;
  model.task.frame = robot.frame;
  const app::ResultsLayout results{dir};
  const app::IdentificationFile ident = app::read_identification(results, model, "");
  const app::TruthFile truth_file = app::read_truth(results, model);
  const Eigen::VectorXd& truth = truth_file.truth;
  const Eigen::Isometry3d cam0_T_world = truth_file.cameras.at(0).camera_T_world;

  // validate's held-out configurations (stages/validate.cpp): drawn from the truth alone.
  calib::MechanismPredictor true_predictor(model, robot.frame);
  std::mt19937 rng(s.seed + 7919);
  const auto configurations =
      calib::sample_actuators(true_predictor, {truth}, static_cast<std::size_t>(held_out), rng);

  const calib::CompensationModels models{&model, ident.start, ident.estimate};
  const auto true_position = [&](const Eigen::VectorXd& readings, const Eigen::VectorXd& seed,
                                 Eigen::Vector3d& out) {
    const auto fk = calib::forward_kinematics(model, truth, readings, robot.frame, seed);
    if (!fk.closure.ok()) return false;
    out = cam0_T_world * fk.pose.translation();
    return true;
  };
  std::vector<Eigen::Vector3d> targets, calibrated, compensated, direct, nominal_targets,
      uncompensated;
  std::vector<calib::TaskTarget> task_targets;
  int refused = 0, failed_execution = 0;
  for (const auto& q : configurations) {
    Eigen::Vector3d target;
    if (!true_position(q, {}, target)) continue;
    const auto cal_fk = calib::forward_kinematics(model, ident.estimate, q, robot.frame);
    if (!cal_fk.closure.ok()) continue;
    calib::TaskTarget t;
    t.pose.translation() = target;
    task_targets.push_back(t);
    const calib::CompensatedTarget c = calib::compensate_target(models, t);
    if (!c.usable()) {
      ++refused;
      continue;
    }
    // The nominal controller commanded to c.commanded: its IK, then the true robot.
    calib::TaskTarget command;
    command.pose.translation() = c.commanded.translation();
    const calib::IkResult controller = calib::solve_ik(model, ident.start, command);
    Eigen::Vector3d executed, by_readings;
    if (!controller.ok() || !true_position(controller.actuator_readings, {}, executed) ||
        !true_position(c.ik.actuator_readings, {}, by_readings)) {
      ++failed_execution;
      continue;
    }
    targets.push_back(target);
    calibrated.emplace_back(cal_fk.pose.translation());
    compensated.push_back(executed);
    direct.push_back(by_readings);
    // Without compensation: the nominal controller commanded to the target itself.
    const calib::IkResult plain = calib::solve_ik(model, ident.start, t);
    Eigen::Vector3d reached;
    if (plain.ok() && true_position(plain.actuator_readings, {}, reached)) {
      nominal_targets.push_back(target);
      uncompensated.push_back(reached);
    }
  }
  const auto cal_stats = calib::position_error_stats(calibrated, targets);
  const auto comp_stats = calib::position_error_stats(compensated, targets);

  // Timing (one core): calibrated IK cold and warm, and the whole compensate_target.
  calib::IkOptions ik_options;
  ik_options.respect_limits = true;
  double t0 = thread_cpu_seconds();
  int ok_cold = 0;
  for (const auto& t : task_targets)
    ok_cold += calib::solve_ik(model, ident.estimate, t, {}, ik_options).ok() ? 1 : 0;
  const double cold_s = seconds_since(t0);
  calib::IkSeed seed;
  t0 = thread_cpu_seconds();
  int ok_warm = 0;
  for (const auto& t : task_targets) {
    const calib::IkResult r = calib::solve_ik(model, ident.estimate, t, seed, ik_options);
    if (r.ok()) {
      ++ok_warm;
      seed = {r.actuator_q, r.passive};
    }
  }
  const double warm_s = seconds_since(t0);
  t0 = thread_cpu_seconds();
  for (const auto& t : task_targets) (void)calib::compensate_target(models, t);
  const double full_s = seconds_since(t0);
  const double n = static_cast<double>(std::max<std::size_t>(task_targets.size(), 1));

  // What `robocal compensate` solves: the calibrated model in the robot file's frame, targets of
  // the tool (the task frame), here the tool positions of the held-out configurations.
  const calib::Mechanism& file_model = robot.model;
  const Eigen::VectorXd file_nominal = file_model.nominal_parameters();
  const Eigen::VectorXd local = calib::calibrated_in_robot_frame(
      file_model, ident.estimate, file_nominal, s.target_mount.empty() ? -1 : robot.frame);
  std::vector<calib::TaskTarget> tool_targets;
  for (const auto& q : configurations) {
    const auto fk = calib::forward_kinematics(file_model, local, q, file_model.task.frame);
    if (!fk.closure.ok()) continue;
    calib::TaskTarget t;
    t.pose.translation() = fk.pose.translation();
    tool_targets.push_back(t);
  }
  const auto time_ik = [&](bool warm, int& converged, double& iterations) {
    calib::IkSeed previous;
    converged = 0;
    iterations = 0.0;
    const double start = thread_cpu_seconds();
    for (const auto& t : tool_targets) {
      const calib::IkResult r =
          calib::solve_ik(file_model, local, t, warm ? previous : calib::IkSeed{}, ik_options);
      iterations += r.iterations / static_cast<double>(tool_targets.size());
      if (r.ok()) {
        ++converged;
        previous = {r.actuator_q, r.passive};
      }
    }
    return seconds_since(start) /
           static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;
  };
  // As compensate_targets seeds: from the nearest target already solved.
  const auto time_nearest_seeded_ik = [&](int& converged, double& iterations) {
    converged = 0;
    iterations = 0.0;
    std::vector<std::pair<Eigen::Vector3d, calib::IkSeed>> solved;
    const double start = thread_cpu_seconds();
    for (const auto& t : tool_targets) {
      calib::IkSeed nearest;
      double best = std::numeric_limits<double>::infinity();
      for (const auto& [position, answer] : solved)
        if (const double d = (position - t.pose.translation()).squaredNorm(); d < best) {
          best = d;
          nearest = answer;
        }
      const calib::IkResult r = calib::solve_ik(file_model, local, t, nearest, ik_options);
      iterations += r.iterations / static_cast<double>(tool_targets.size());
      if (r.ok()) {
        ++converged;
        solved.emplace_back(t.pose.translation(), calib::IkSeed{r.actuator_q, r.passive});
      }
    }
    return seconds_since(start) /
           static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;
  };
  int tool_nearest_ok = 0;
  double tool_nearest_iterations = 0.0;
  const double tool_nearest_us = time_nearest_seeded_ik(tool_nearest_ok, tool_nearest_iterations);
  // A path: 500 targets 0.5 mm apart on a 40 mm circle around the first held-out tool position
  // (what a G-code move asks), each seeded by its predecessor.
  std::vector<calib::TaskTarget> path;
  if (!tool_targets.empty()) {
    const Eigen::Vector3d centre = tool_targets.front().pose.translation();
    for (int k = 0; k < 500; ++k) {
      const double a = 0.5e-3 * k / 0.04;
      calib::TaskTarget t;
      t.pose.translation() = centre + 0.04 * Eigen::Vector3d(std::cos(a) - 1.0, std::sin(a), 0.0);
      path.push_back(t);
    }
  }
  int path_ok = 0;
  double path_iterations = 0.0;
  t0 = thread_cpu_seconds();
  {
    calib::IkSeed previous;
    for (const auto& t : path) {
      const calib::IkResult r = calib::solve_ik(file_model, local, t, previous, ik_options);
      path_iterations += r.iterations / static_cast<double>(path.size());
      if (r.ok()) {
        ++path_ok;
        previous = {r.actuator_q, r.passive};
      }
    }
  }
  const double path_us =
      seconds_since(t0) / static_cast<double>(std::max<std::size_t>(path.size(), 1)) * 1e6;
  int tool_cold_ok = 0, tool_warm_ok = 0;
  double tool_cold_iterations = 0.0, tool_warm_iterations = 0.0;
  const double tool_cold_us = time_ik(false, tool_cold_ok, tool_cold_iterations);
  const double tool_warm_us = time_ik(true, tool_warm_ok, tool_warm_iterations);
  const calib::CompensationModels tool_models{&file_model, file_nominal, local};
  t0 = thread_cpu_seconds();
  (void)calib::compensate_targets(tool_models, tool_targets);
  const double tool_full_us =
      seconds_since(t0) / static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;

  // The reusable calib::Compensator (what compensate_targets runs on a list): calibrated IK with
  // its verdict plus the nominal model's FK, per target. Cold: each target from the closed form of
  // its own position; warm: from the previous target's answer. Built inside the timed region.
  calib::Compensator::Counts cold_counts, warm_counts;
  const auto time_compensator = [&](bool warm, int& usable, double& iterations) {
    usable = 0;
    iterations = 0.0;
    const double start = thread_cpu_seconds();
    calib::Compensator compensator(tool_models);
    calib::IkSeed previous;
    for (const auto& t : tool_targets) {
      const calib::CompensatedTarget c =
          compensator.compensate(t, warm ? previous : calib::IkSeed{});
      iterations += c.ik.iterations / static_cast<double>(tool_targets.size());
      if (c.usable()) {
        ++usable;
        previous = {c.ik.actuator_q, c.ik.passive};
      }
    }
    const double us = seconds_since(start) /
                      static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;
    (warm ? warm_counts : cold_counts) = compensator.counts();
    return us;
  };
  int compensator_cold_usable = 0, compensator_warm_usable = 0;
  double compensator_cold_iterations = 0.0, compensator_warm_iterations = 0.0;
  const double compensator_cold_us =
      time_compensator(false, compensator_cold_usable, compensator_cold_iterations);
  const double compensator_warm_us =
      time_compensator(true, compensator_warm_usable, compensator_warm_iterations);
  // The calibrated IK alone ("calibrated IK per target"): Compensator::calibrated_ik,
  // the first half of compensate(), cold (closed-form seed) and warm from the previous answer;
  // the Compensator built inside the timed region, as above.
  const auto time_calibrated_ik = [&](bool warm, int& ok) {
    ok = 0;
    const double start = thread_cpu_seconds();
    calib::Compensator compensator(tool_models);
    calib::IkSeed previous;
    for (const auto& t : tool_targets) {
      const calib::IkResult ik = compensator.calibrated_ik(t, warm ? previous : calib::IkSeed{});
      if (ik.ok() && ik.mode.acceptable()) {
        ++ok;
        previous = {ik.actuator_q, ik.passive};
      }
    }
    return seconds_since(start) /
           static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;
  };
  int calibrated_ik_cold_ok = 0, calibrated_ik_warm_ok = 0;
  const double calibrated_ik_cold_us = time_calibrated_ik(false, calibrated_ik_cold_ok);
  const double calibrated_ik_warm_us = time_calibrated_ik(true, calibrated_ik_warm_ok);

  // The same work by the general solvers (compensate_target before calib::Compensator): solve_ik
  // then the nominal forward_kinematics, per target, cold and warm from the previous answer.
  const auto time_general = [&](bool warm, int& usable) {
    usable = 0;
    calib::IkSeed previous;
    const double start = thread_cpu_seconds();
    for (const auto& t : tool_targets) {
      const calib::IkResult ik =
          calib::solve_ik(file_model, local, t, warm ? previous : calib::IkSeed{}, ik_options);
      if (!ik.ok() || !ik.mode.acceptable()) continue;
      const auto fk = calib::forward_kinematics(file_model, file_nominal, ik.actuator_readings,
                                                file_model.task.frame, ik.passive);
      if (fk.closure.ok() && fk.closure.mode.verdict != calib::ModeVerdict::kOther) {
        ++usable;
        previous = {ik.actuator_q, ik.passive};
      }
    }
    return seconds_since(start) /
           static_cast<double>(std::max<std::size_t>(tool_targets.size(), 1)) * 1e6;
  };
  int general_cold_usable = 0, general_warm_usable = 0;
  const double general_cold_us = time_general(false, general_cold_usable);
  const double general_warm_us = time_general(true, general_warm_usable);

  // Agreement with the general solvers: verdicts and commands, cold, per target; and the
  // calibrated FK of the compensator's readings against the target.
  int verdict_mismatches = 0;
  double max_commanded_difference = 0.0, max_reached_error = 0.0;
  {
    calib::Compensator compensator(tool_models);
    for (const auto& t : tool_targets) {
      const calib::CompensatedTarget c = compensator.compensate(t);
      const calib::IkResult ik = calib::solve_ik(file_model, local, t, {}, ik_options);
      bool reference_usable = ik.ok() && ik.mode.acceptable();
      Eigen::Vector3d reference_commanded = Eigen::Vector3d::Zero();
      if (reference_usable) {
        const auto fk = calib::forward_kinematics(file_model, file_nominal, ik.actuator_readings,
                                                  file_model.task.frame, ik.passive);
        reference_usable = fk.closure.ok() && fk.closure.mode.verdict != calib::ModeVerdict::kOther;
        reference_commanded = fk.pose.translation();
      }
      if (reference_usable != c.usable() ||
          (reference_usable && ik.mode.verdict != c.ik.mode.verdict)) {
        ++verdict_mismatches;
        continue;
      }
      if (!c.usable()) continue;
      max_commanded_difference = std::max(max_commanded_difference,
                                          (c.commanded.translation() - reference_commanded).norm());
      const auto reached = calib::forward_kinematics(file_model, local, c.ik.actuator_readings,
                                                     file_model.task.frame);
      max_reached_error =
          std::max(max_reached_error,
                   reached.closure.ok() ? (reached.pose.translation() - t.pose.translation()).norm()
                                        : std::numeric_limits<double>::infinity());
    }
  }

  const nlohmann::json out = {
      {"session", dir.string()},
      {"robot", model.name},
      {"held_out_requested", held_out},
      {"targets", task_targets.size()},
      {"refused", refused},
      {"failed_execution", failed_execution},
      {"calibrated_model_held_out", stats_json(cal_stats)},
      {"compensated_through_nominal_controller", stats_json(comp_stats)},
      {"compensated_by_readings", stats_json(calib::position_error_stats(direct, targets))},
      {"uncompensated_nominal_controller",
       stats_json(calib::position_error_stats(uncompensated, nominal_targets))},
      {"ratio_compensated_to_calibrated_rms", comp_stats.rms / cal_stats.rms},
      {"calibrated_ik_cold_us_per_target", cold_s / n * 1e6},
      {"calibrated_ik_warm_us_per_target", warm_s / n * 1e6},
      {"calibrated_ik_cold_converged", ok_cold},
      {"calibrated_ik_warm_converged", ok_warm},
      {"compensate_target_us_per_target", full_s / n * 1e6},
      {"robot_frame_tool_targets", tool_targets.size()},
      {"robot_frame_calibrated_ik_cold_us_per_target", tool_cold_us},
      {"robot_frame_calibrated_ik_warm_us_per_target", tool_warm_us},
      {"robot_frame_calibrated_ik_cold_converged", tool_cold_ok},
      {"robot_frame_calibrated_ik_cold_iterations", tool_cold_iterations},
      {"robot_frame_calibrated_ik_warm_iterations", tool_warm_iterations},
      {"robot_frame_calibrated_ik_warm_converged", tool_warm_ok},
      {"robot_frame_calibrated_ik_nearest_seed_us_per_target", tool_nearest_us},
      {"robot_frame_calibrated_ik_nearest_seed_iterations", tool_nearest_iterations},
      {"robot_frame_calibrated_ik_nearest_seed_converged", tool_nearest_ok},
      {"robot_frame_calibrated_ik_path_us_per_target", path_us},
      {"robot_frame_calibrated_ik_path_iterations", path_iterations},
      {"robot_frame_calibrated_ik_path_converged", path_ok},
      {"robot_frame_compensate_targets_us_per_target", tool_full_us},
      {"robot_frame_general_solvers_cold_us_per_target", general_cold_us},
      {"robot_frame_general_solvers_cold_usable", general_cold_usable},
      {"robot_frame_general_solvers_warm_us_per_target", general_warm_us},
      {"robot_frame_general_solvers_warm_usable", general_warm_usable},
      {"robot_frame_compensator_calibrated_ik_cold_us_per_target", calibrated_ik_cold_us},
      {"robot_frame_compensator_calibrated_ik_cold_ok", calibrated_ik_cold_ok},
      {"robot_frame_compensator_calibrated_ik_warm_us_per_target", calibrated_ik_warm_us},
      {"robot_frame_compensator_calibrated_ik_warm_ok", calibrated_ik_warm_ok},
      {"robot_frame_compensator_cold_us_per_target", compensator_cold_us},
      {"robot_frame_compensator_cold_usable", compensator_cold_usable},
      {"robot_frame_compensator_cold_iterations", compensator_cold_iterations},
      {"robot_frame_compensator_cold_general_ik", cold_counts.general_ik},
      {"robot_frame_compensator_cold_general_fk", cold_counts.general_fk},
      {"robot_frame_compensator_warm_us_per_target", compensator_warm_us},
      {"robot_frame_compensator_warm_general_ik", warm_counts.general_ik},
      {"robot_frame_compensator_warm_general_fk", warm_counts.general_fk},
      {"robot_frame_compensator_warm_usable", compensator_warm_usable},
      {"robot_frame_compensator_warm_iterations", compensator_warm_iterations},
      {"robot_frame_compensator_vs_general_verdict_mismatches", verdict_mismatches},
      {"robot_frame_compensator_vs_general_max_commanded_difference_m", max_commanded_difference},
      {"robot_frame_compensator_max_calibrated_fk_error_m", max_reached_error}};
  std::cout << out.dump(2) << "\n";
  return comp_stats.rms <= 1.1 * cal_stats.rms ? 0 : 1;
}
