#include "robocal/calib/compensation.hpp"

#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closure.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>

namespace robocal::calib {

const char* to_string(TargetVerdict verdict) {
  switch (verdict) {
    case TargetVerdict::kOk:
      return "ok";
    case TargetVerdict::kAmbiguous:
      return "ambiguous";
    case TargetVerdict::kOtherMode:
      return "other_mode";
    case TargetVerdict::kUnreachable:
      return "unreachable";
  }
  return "?";
}

namespace {

void check_models(const CompensationModels& models) {
  if (models.model == nullptr) throw std::invalid_argument("compensation: no mechanism given");
  const auto n = static_cast<Eigen::Index>(models.model->parameters.size());
  if (models.nominal.size() != n || models.calibrated.size() != n)
    throw std::invalid_argument("compensation: parameter vectors do not match the mechanism");
}

TaskTarget position_target(const Eigen::Vector3d& p) {
  TaskTarget t;
  t.pose.translation() = p;
  return t;
}

}  // namespace

CompensatedTarget compensate_target(const CompensationModels& models, const TaskTarget& target,
                                    const IkSeed& seed) {
  check_models(models);
  const Mechanism& model = *models.model;
  CompensatedTarget out;
  IkOptions options;
  // A command outside the joint limits is not a command the robot can execute.
  options.respect_limits = true;
  out.ik = solve_ik(model, models.calibrated, target, seed, options);
  if (out.ik.status == SolveStatus::kOtherMode) {
    out.verdict = TargetVerdict::kOtherMode;
    out.problem = "the calibrated robot reaches it only on " + out.ik.mode.describe();
    return out;
  }
  if (!out.ik.ok()) {
    out.verdict = TargetVerdict::kUnreachable;
    out.problem = fmt::format(
        "the calibrated robot cannot reach it within its joint limits (inverse kinematics: {}, "
        "residual {:.3g} m)",
        to_string(out.ik.status), out.ik.residual);
    return out;
  }
  if (out.ik.mode.verdict == ModeVerdict::kOther) {
    out.verdict = TargetVerdict::kOtherMode;
    out.problem = "the calibrated robot reaches it only on " + out.ik.mode.describe();
    return out;
  }
  // What a controller running the nominal model believes these readings do.
  const ForwardResult fk = forward_kinematics(model, models.nominal, out.ik.actuator_readings,
                                              model.task.frame, out.ik.passive);
  if (!fk.closure.ok() || fk.closure.mode.verdict == ModeVerdict::kOther) {
    out.verdict = TargetVerdict::kUnreachable;
    out.problem = fmt::format(
        "the nominal model cannot assemble at the calibrated readings (closure: {}{}), so no "
        "task-space command for the nominal controller produces them",
        to_string(fk.closure.status),
        fk.closure.mode.verdict == ModeVerdict::kOther ? "; " + fk.closure.mode.describe() : "");
    return out;
  }
  out.commanded = fk.pose;
  if (out.ik.mode.verdict == ModeVerdict::kAmbiguous) {
    out.verdict = TargetVerdict::kAmbiguous;
    out.problem = "near a configuration where assembly modes meet: " + out.ik.mode.describe();
  } else {
    out.verdict = TargetVerdict::kOk;
  }
  return out;
}

std::vector<CompensatedTarget> compensate_targets(const CompensationModels& models,
                                                  const std::vector<TaskTarget>& targets) {
  std::vector<CompensatedTarget> out;
  out.reserve(targets.size());
  std::vector<std::size_t> solved;  // indices of usable answers (seed candidates)
  // Distance between two targets: position, plus the joint value for joint tasks and the
  // rotation (weighted as 0.1 m per rad) for pose tasks.
  const auto distance = [&](const TaskTarget& a, const TaskTarget& b) {
    double d = (a.pose.translation() - b.pose.translation()).squaredNorm() +
               (a.joint_value - b.joint_value) * (a.joint_value - b.joint_value);
    if (models.model != nullptr && models.model->task.type == TaskType::kPose)
      d += 0.01 * (a.pose.linear().transpose() * b.pose.linear() - Eigen::Matrix3d::Identity())
                      .squaredNorm();
    return d;
  };
  for (std::size_t k = 0; k < targets.size(); ++k) {
    IkSeed seed;
    double best = std::numeric_limits<double>::infinity();
    for (const std::size_t j : solved) {
      const double d = distance(targets[k], targets[j]);
      if (d < best) {
        best = d;
        seed = {out[j].ik.actuator_q, out[j].ik.passive};
      }
    }
    out.push_back(compensate_target(models, targets[k], seed));
    // A warm start may land on another mode or fail where a cold start would not: retry cold.
    if (!out.back().usable() && !solved.empty()) out.back() = compensate_target(models, targets[k]);
    if (out.back().usable()) solved.push_back(k);
  }
  return out;
}

bool executed_position(const CompensationModels& models, const Eigen::VectorXd& params,
                       const Eigen::Vector3d& commanded, Eigen::Vector3d& reached, std::string& why,
                       const IkSeed& seed) {
  check_models(models);
  const Mechanism& model = *models.model;
  const IkResult ik = solve_ik(model, models.nominal, position_target(commanded), seed);
  if (!ik.ok()) {
    why = fmt::format("the nominal controller cannot reach ({:.6f}, {:.6f}, {:.6f}) m: {}",
                      commanded.x(), commanded.y(), commanded.z(), to_string(ik.status));
    return false;
  }
  const ForwardResult fk =
      forward_kinematics(model, params, ik.actuator_readings, model.task.frame, ik.passive);
  if (!fk.closure.ok()) {
    why = fmt::format(
        "the robot cannot assemble at the nominal controller's readings for "
        "({:.6f}, {:.6f}, {:.6f}) m: {}",
        commanded.x(), commanded.y(), commanded.z(), to_string(fk.closure.status));
    return false;
  }
  reached = fk.pose.translation();
  return true;
}

namespace {

struct SegmentRefiner {
  const CompensationModels& models;
  const Eigen::Vector3d& from;
  const Eigen::Vector3d& to;
  const SegmentOptions& options;
  CompensatedSegment& out;

  [[nodiscard]] Eigen::Vector3d meant(double s) const { return from + s * (to - from); }

  // Largest distance between where the calibrated robot goes while the nominal controller runs
  // straight from c0 to c1, and where the meant line is at the same fraction.
  bool deviation(double s0, const Eigen::Vector3d& c0, double s1, const Eigen::Vector3d& c1,
                 const IkSeed& seed, double& worst) const {
    worst = 0.0;
    for (const double t : std::array<double, 3>{0.25, 0.5, 0.75}) {
      Eigen::Vector3d reached;
      std::string why;
      if (!executed_position(models, models.calibrated, c0 + t * (c1 - c0), reached, why, seed)) {
        out.problem = why;
        return false;
      }
      worst = std::max(worst, (reached - meant(s0 + t * (s1 - s0))).norm());
    }
    return true;
  }

  // Appends the pieces of [s0, s1] (c0, c1: their commanded ends; seed: the calibrated IK
  // answer at s0) after s0.
  bool refine(double s0, const Eigen::Vector3d& c0, double s1, const Eigen::Vector3d& c1,
              const IkSeed& seed, int depth) {
    double worst = 0.0;
    if (!deviation(s0, c0, s1, c1, seed, worst)) return false;
    if (worst <= options.tolerance) {
      out.fractions.push_back(s1);
      out.commanded.push_back(c1);
      out.max_deviation = std::max(out.max_deviation, worst);
      return true;
    }
    if (depth >= options.max_depth) {
      out.problem = fmt::format(
          "the move cannot be kept within {:.3g} m of the straight line after {} bisections "
          "(still {:.3g} m off near {:.0f} % of it)",
          options.tolerance, depth, worst, 100.0 * (s0 + s1) / 2.0);
      return false;
    }
    const double sm = 0.5 * (s0 + s1);
    const CompensatedTarget mid = compensate_target(models, position_target(meant(sm)), seed);
    if (!mid.usable()) {
      const Eigen::Vector3d p = meant(sm);
      out.problem = fmt::format("the point ({:.6f}, {:.6f}, {:.6f}) m on the move: {}", p.x(),
                                p.y(), p.z(), mid.problem);
      return false;
    }
    const Eigen::Vector3d cm = mid.commanded.translation();
    const IkSeed mid_seed{mid.ik.actuator_q, mid.ik.passive};
    return refine(s0, c0, sm, cm, seed, depth + 1) && refine(sm, cm, s1, c1, mid_seed, depth + 1);
  }
};

}  // namespace

CompensatedSegment compensate_segment(const CompensationModels& models, const Eigen::Vector3d& from,
                                      const Eigen::Vector3d& from_commanded,
                                      const Eigen::Vector3d& to, const SegmentOptions& options,
                                      const IkSeed& from_seed) {
  check_models(models);
  if (models.model->task.type != TaskType::kPosition)
    throw std::invalid_argument("compensate_segment: the robot's task is not a position");
  CompensatedSegment out;
  CompensatedTarget end = compensate_target(models, position_target(to), from_seed);
  // A warm start may fail where a cold one would not (a long move): retry cold.
  if (!end.usable() && from_seed.actuator_q.size() > 0)
    end = compensate_target(models, position_target(to));
  if (!end.usable()) {
    out.problem = fmt::format("the end point ({:.6f}, {:.6f}, {:.6f}) m: {}", to.x(), to.y(),
                              to.z(), end.problem);
    return out;
  }
  SegmentRefiner refiner{models, from, to, options, out};
  out.end_seed = {end.ik.actuator_q, end.ik.passive};
  out.ok = refiner.refine(0.0, from_commanded, 1.0, end.commanded.translation(), from_seed, 0);
  return out;
}

Eigen::VectorXd calibrated_in_robot_frame(const Mechanism& model, const Eigen::VectorXd& estimate,
                                          const Eigen::VectorXd& file_nominal, int mount_body) {
  const auto n = static_cast<Eigen::Index>(model.parameters.size());
  if (estimate.size() != n || file_nominal.size() != n)
    throw std::invalid_argument("calibrated_in_robot_frame: parameter vectors do not match");
  Eigen::VectorXd out = estimate;
  for (Eigen::Index i = 0; i < n; ++i) {
    const int body = model.parameters[static_cast<std::size_t>(i)].body;
    const bool base_frame = body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0;
    if (base_frame || (mount_body >= 0 && body == mount_body)) out[i] = file_nominal[i];
  }
  return out;
}

}  // namespace robocal::calib
