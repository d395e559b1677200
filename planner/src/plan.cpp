// Planning end to end (see plan.hpp).
#include "robocal/planner/plan.hpp"

#include "robocal/planner/task_sampling.hpp"

#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <iterator>
#include <random>
#include <sstream>

namespace robocal::planner {

int target_frame(const calib::Mechanism& model, const Cell& cell) {
  if (cell.target.frame.empty()) return model.tool;
  return model.body_index(cell.target.frame);
}

std::string check_cell(const calib::Mechanism& model, const Eigen::VectorXd& params,
                       const Cell& cell) {
  std::ostringstream err;
  const int frame = target_frame(model, cell);
  if (frame < 0)
    return cell.source + ":" + std::to_string(cell.target.line) + ": target.frame '" +
           cell.target.frame + "' is not a body of robot '" + model.name + "'";
  // The robot's reach: distance of the measured frame from the base over a few configurations.
  FeasibilityOptions fo = feasibility_options_from_cell(cell);
  ReachChecker reach(model, params, fo.reach);
  Eigen::VectorXd lo, hi;
  reach.reading_limits(lo, hi);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> reached;
  // How the samples failed, by verdict, with the first failing readings of each: what a robot
  // that assembles nowhere is told (rods too short fail on closure, degrees on the limits).
  std::array<int, 7> failed{};
  std::array<Eigen::VectorXd, 7> failed_at;
  std::array<std::string, 7> failed_detail;
  for (int k = 0; k < 400 && reached.size() < 60; ++k) {
    Eigen::VectorXd x(lo.size());
    for (Eigen::Index i = 0; i < lo.size(); ++i) x(i) = lo(i) + u(rng) * (hi(i) - lo(i));
    const ReachResult r = reach.reach_check(x);
    if (r.ok()) {
      reached.emplace_back(r.body_poses[static_cast<std::size_t>(frame)].translation());
    } else {
      const auto v = static_cast<std::size_t>(r.verdict);
      if (failed[v]++ == 0) {
        failed_at[v] = x;
        failed_detail[v] = r.detail;
      }
    }
  }
  if (reached.empty()) {
    const auto most = static_cast<std::size_t>(
        std::distance(failed.begin(), std::max_element(failed.begin(), failed.end())));
    std::ostringstream readings;
    for (Eigen::Index i = 0; i < failed_at[most].size(); ++i)
      readings << (i > 0 ? ", " : "") << failed_at[most](i);
    const std::string file = model.source.empty() ? std::string("the robot file") : model.source;
    return (model.source.empty() ? std::string() : model.source + ": ") + "robot '" + model.name +
           "' cannot assemble: it assembles at none of 400 sampled actuator positions within its "
           "limits and the cell's joint margin (" +
           std::to_string(failed[most]) + " failed with '" +
           to_string(static_cast<ReachVerdict>(most)) + "', e.g. at actuator readings [" +
           readings.str() + "]" +
           (failed_detail[most].empty() ? std::string() : ": " + failed_detail[most]) +
           "); check its lengths (metres) and joint limits (`robocal kin check " + file + "`)";
  }
  double reach_radius = 0.0;
  for (const Eigen::Vector3d& p : reached) reach_radius = std::max(reach_radius, p.norm());
  const double plausible = 100.0 * std::max(reach_radius, 0.1);
  auto too_far = [&](const Eigen::Vector3d& p) { return p.norm() > plausible; };
  const std::string unit_hint =
      " m from the robot's base, but the robot reaches only " + std::to_string(reach_radius) +
      " m: the cell's lengths look like millimetres (cell files are in metres; write 'units: mm' "
      "at the top if the file is in millimetres)";
  if (cell.workspace.declared && (too_far(cell.workspace.min) || too_far(cell.workspace.max)))
    return cell.source + ":" + std::to_string(cell.workspace.line) + ": the workspace extends to " +
           std::to_string(std::max(cell.workspace.min.norm(), cell.workspace.max.norm())) +
           unit_hint;
  for (const CellCamera& c : cell.cameras)
    if (too_far(c.world_T_camera.translation()))
      return cell.source + ":" + std::to_string(c.line) + ": camera '" + c.name + "' is " +
             std::to_string(c.world_T_camera.translation().norm()) + unit_hint;
  for (const Obstacle& o : cell.obstacles)
    if (too_far(o.world_T_obstacle.translation()))
      return cell.source + ":" + std::to_string(o.line) + ": obstacle '" + o.name + "' is " +
             std::to_string(o.world_T_obstacle.translation().norm()) + unit_hint;
  // An obstacle that encloses the robot's base (the fixed bodies hanging from the world).
  CollisionScene scene(model, cell, fo.collision);
  std::vector<Eigen::Isometry3d> poses;
  calib::JointState home;
  home.q = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()));
  calib::body_poses(model, params, home, poses);
  for (std::size_t b = 0; b < model.bodies.size(); ++b) {
    if (model.bodies[b].parent >= 0) continue;
    for (const std::string& name : scene.obstacles_containing(poses[b].translation())) {
      int line = 0;
      for (const Obstacle& o : cell.obstacles)
        if (o.name == name) line = o.line;
      return cell.source + ":" + std::to_string(line) + ": obstacle '" + name +
             "' encloses the robot's base (" + model.bodies[b].name + " at " +
             [&] {
               std::ostringstream s;
               s << poses[b].translation().transpose();
               return s.str();
             }() +
             "): the robot would start inside it; check its centre and size";
    }
  }
  for (const CellCamera& c : cell.cameras)
    for (const std::string& name : scene.obstacles_containing(c.world_T_camera.translation()))
      return cell.source + ":" + std::to_string(c.line) + ": camera '" + c.name +
             "' sits inside obstacle '" + name + "'";
  // A required camera that sees no part of the reachable region (its centre in front of the
  // camera and inside the image).
  for (const int ci : cell.required_cameras()) {
    const CellCamera& c = cell.cameras[static_cast<std::size_t>(ci)];
    const Eigen::Isometry3d cTw = c.world_T_camera.inverse();
    int seen = 0;
    for (const Eigen::Vector3d& p : reached) {
      const auto px = vision::project(c.model, cTw * p);
      if (px && vision::in_image(c.model, *px)) ++seen;
    }
    if (seen == 0)
      return cell.source + ":" + std::to_string(c.line) + ": camera '" + c.name +
             "' cannot see the robot's working volume at all (none of " +
             std::to_string(reached.size()) +
             " reachable positions of the measured frame projects into its image): check its "
             "position and viewing direction (look_at)";
  }
  return err.str();
}

namespace {

// Drops from `tour` the poses no free straight motion reaches at the safety guard's step (a
// near-touch between two of the planner's coarser samples), saying why in its problems.
void recheck_at_guard_step(const FeasibilityChecker& checker,
                           const std::vector<Eigen::VectorXd>& chosen, const PlanOptions& options,
                           Tour& tour) {
  Eigen::VectorXd from = options.start;
  std::vector<std::size_t> order;
  for (const std::size_t k : tour.order) {
    std::string why;
    if (from.size() == 0 || checker.segment_free(from, chosen[k], options.guard_step, &why)) {
      order.push_back(k);
      from = chosen[k];
    } else {
      tour.complete = false;
      tour.problems.push_back("pose " + std::to_string(k) +
                              " cannot be reached by a free straight motion from the "
                              "tour at the safety guard's step (" +
                              why + ")");
    }
  }
  tour.order = std::move(order);
}

// The poses already measured (options.measured) into res.measured; those that assemble on the
// intended mode also into `readings`, their indices in `measured_idx`.
void add_measured_poses(const FeasibilityChecker& checker, const PlanOptions& options,
                        PlanResult& res, std::vector<Eigen::VectorXd>& readings,
                        std::vector<std::size_t>& measured_idx) {
  for (std::size_t k = 0; k < options.measured.size(); ++k) {
    Candidate c = checker.evaluate(options.measured[k]);
    PlannedPose p;
    p.id = "measured" + std::to_string(k + 1);
    p.readings = options.measured[k];
    p.candidate = c;
    res.measured.push_back(p);
    const ReachResult r = checker.reach().reach_check(options.measured[k]);
    if (!r.ok()) {
      res.warnings.push_back(p.id + " cannot be assembled on the intended mode (" +
                             std::string(to_string(r.verdict)) + "); ignored for the selection");
      continue;
    }
    measured_idx.push_back(readings.size());
    readings.push_back(options.measured[k]);
  }
}

}  // namespace

PlanResult plan_measurements(const calib::Mechanism& model, const Eigen::VectorXd& params,
                             const Cell& cell, const PlanOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  PlanResult res;
  auto say = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  const std::string bad = check_cell(model, params, cell);
  if (!bad.empty()) {
    res.status = PlanStatus::kBadCell;
    res.message = bad;
    return res;
  }
  res.frame = target_frame(model, cell);
  FeasibilityOptions feasibility = feasibility_options_from_cell(cell);
  feasibility.tolerance_sigma = options.tolerance_sigma;
  const FeasibilityChecker checker(model, params, cell, res.frame, feasibility);
  const bool task_space = options.task_space && task_space_sampling_applies(checker);
  say("sampling " + std::to_string(options.pool) + " candidate poses in " +
      (task_space ? "task space (target turned towards the cameras)" : "joint space"));
  std::mt19937 rng(options.seed);
  std::vector<Candidate> sampled =
      task_space ? sample_facing_cameras(checker, options.pool, rng, &res.counts)
                 : checker.sample(options.pool, rng, &res.counts);
  std::size_t not_admissible = 0;
  for (Candidate& c : sampled) {
    if (!c.feasible()) continue;
    if (options.admissible && !options.admissible(c.readings)) {
      ++not_admissible;
      continue;
    }
    res.pool.push_back(std::move(c));
  }
  say(res.counts.summary());
  if (not_admissible > 0)
    say(std::to_string(not_admissible) +
        " feasible candidates the controller cannot command left out");
  // Sequential mode: the measured poses join the pool (first) so the selection knows them.
  std::vector<Eigen::VectorXd> readings;
  std::vector<std::size_t> measured_idx;
  add_measured_poses(checker, options, res, readings, measured_idx);
  const std::size_t offset = readings.size();
  const auto L_guess = static_cast<std::size_t>(6);
  std::vector<Eigen::VectorXd> chosen;
  std::vector<const Candidate*> chosen_c;
  // Selected poses that no collision-free straight motion joins to the tour (a linear delta's
  // carriages moving straight sweep the effector past a tower) leave the pool, and the poses are
  // selected again from the rest: up to three rounds.
  std::size_t dropped = 0;
  std::size_t identifiable = 0;
  for (int round = 0;; ++round) {
    readings.resize(offset);
    for (const Candidate& c : res.pool) readings.push_back(c.readings);
    if (res.pool.size() < std::max<std::size_t>(options.selection.count / 2, L_guess)) {
      res.status = PlanStatus::kInfeasible;
      res.message = "too few feasible candidate poses to plan (" + std::to_string(res.pool.size()) +
                    "): " + res.counts.summary();
      return res;
    }
    say("identification Jacobians of " + std::to_string(readings.size()) + " poses");
    calib::MechanismPredictor predictor(model, res.frame);
    const ObservabilityModel obs =
        build_observability_model(predictor, params, readings, options.observability);
    res.identifiability = obs.messages;
    identifiable = obs.columns();
    say("selecting " + std::to_string(options.selection.count) + " poses by " +
        to_string(options.selection.index) + " over " + std::to_string(obs.columns()) +
        " identifiable parameters");
    // Selection works on pool indices: measured poses are readings[0..offset).
    res.selection = select_poses(obs, options.selection, measured_idx);
    chosen.clear();
    chosen_c.clear();
    std::vector<std::size_t> chosen_pool;
    for (const std::size_t i : res.selection.chosen) {
      if (i < offset) continue;
      chosen.push_back(readings[i]);
      chosen_c.push_back(&res.pool[i - offset]);
      chosen_pool.push_back(i - offset);
    }
    if (!options.order) {
      res.tour = Tour{};
      for (std::size_t k = 0; k < chosen.size(); ++k) res.tour.order.push_back(k);
      res.tour.complete = true;
      break;
    }
    say("ordering " + std::to_string(chosen.size()) +
        " poses into a short tour, every motion checked for collisions");
    const double step = options.motion_step;
    res.tour = plan_tour(
        chosen,
        [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, std::string* why) {
          return checker.segment_free(a, b, step, why);
        },
        options.start);
    // The tour's own motions at the guard's step: a near-touch between two coarse samples
    // (a carriage 20 mm apart) is not joined either.
    if (res.tour.complete && options.guard_step > 0.0 && options.guard_step < step)
      recheck_at_guard_step(checker, chosen, options, res.tour);
    if (res.tour.complete || round == 2) {
      for (const std::string& p : res.tour.problems) res.warnings.push_back(p);
      break;
    }
    std::vector<bool> joined(chosen.size(), false);
    for (const std::size_t k : res.tour.order) joined[k] = true;
    std::vector<bool> drop(res.pool.size(), false);
    for (std::size_t k = 0; k < chosen.size(); ++k)
      if (!joined[k]) drop[chosen_pool[k]] = true;
    std::vector<Candidate> kept;
    kept.reserve(res.pool.size());
    for (std::size_t i = 0; i < res.pool.size(); ++i)
      if (!drop[i]) kept.push_back(std::move(res.pool[i]));
    dropped += res.pool.size() - kept.size();
    res.pool = std::move(kept);
  }
  if (res.pool.size() * 6 < identifiable)
    res.warnings.push_back("only " + std::to_string(res.pool.size()) + " feasible poses for " +
                           std::to_string(identifiable) + " identifiable parameters");
  if (dropped > 0)
    res.warnings.push_back(std::to_string(dropped) +
                           " selected poses no collision-free straight motion joined to the tour "
                           "were left out of the pool and the poses selected again");
  for (std::size_t k = 0; k < res.tour.order.size(); ++k) {
    const std::size_t i = res.tour.order[k];
    PlannedPose p;
    p.id = "pose" + std::to_string(k + 1);
    p.readings = chosen[i];
    p.candidate = *chosen_c[i];
    res.poses.push_back(std::move(p));
  }
  res.plan_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!res.tour.complete) {
    res.status = PlanStatus::kInfeasible;
    res.message = "the selected poses cannot all be joined by collision-free motions: " +
                  (res.tour.problems.empty() ? std::string("?") : res.tour.problems.front());
  } else if (!res.selection.accepted) {
    res.status = PlanStatus::kNotAccepted;
    res.message = res.selection.message;
  } else {
    res.status = PlanStatus::kOk;
    res.message = res.selection.message;
  }
  return res;
}

PlanResult plan_with_enough_candidates(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                       const Cell& cell, PlanOptions& options, std::size_t enough,
                                       std::size_t max_pool) {
  PlanResult res = plan_measurements(model, params, cell, options);
  const std::size_t want = 10 * options.selection.count;
  if (res.pool.size() >= (enough > 0 ? enough : want) || res.status == PlanStatus::kBadCell)
    return res;
  const double rate = static_cast<double>(std::max<std::size_t>(res.pool.size(), 1)) /
                      static_cast<double>(std::max<std::size_t>(res.counts.evaluated, 1));
  const auto more = static_cast<std::size_t>(
      std::min(static_cast<double>(max_pool), static_cast<double>(want) / rate));
  if (more <= options.pool) return res;
  options.pool = more;
  return plan_measurements(model, params, cell, options);
}

}  // namespace robocal::planner
