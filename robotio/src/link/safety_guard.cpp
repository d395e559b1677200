#include "robocal/robotio/safety_guard.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace robocal::robotio {
namespace {

std::string vec_text(const Eigen::VectorXd& v) {
  std::vector<double> x(v.data(), v.data() + v.size());
  return fmt::format("[{:.6g}]", fmt::join(x, ", "));
}

}  // namespace

SafetyGuard::SafetyGuard(const calib::Mechanism& model, Eigen::VectorXd params, SafetyLimits limits)
    : model_(&model), params_(std::move(params)), limits_(std::move(limits)) {
  const auto n = static_cast<Eigen::Index>(model.actuated.size());
  if (limits_.actuator_lower.size() != n || limits_.actuator_upper.size() != n)
    default_actuator_limits(model, params_, limits_);
  joint_per_reading_ = calib::encoder_scales(model, params_).cwiseAbs();
}

void SafetyGuard::default_actuator_limits(const calib::Mechanism& model,
                                          const Eigen::VectorXd& params, SafetyLimits& limits) {
  const auto n = static_cast<Eigen::Index>(model.actuated.size());
  Eigen::VectorXd lo(n), hi(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const calib::JointLimits& l = model.bodies[model.actuated[static_cast<std::size_t>(i)]].limits;
    lo[i] = l.lower;
    hi[i] = l.upper;
  }
  // Readings from joint values through the encoder model; a negative scale swaps the ends.
  const Eigen::VectorXd a = calib::readings_from_joint_values(model, params, lo);
  const Eigen::VectorXd b = calib::readings_from_joint_values(model, params, hi);
  limits.actuator_lower = a.cwiseMin(b);
  limits.actuator_upper = a.cwiseMax(b);
}

void SafetyGuard::arm(const std::string& operator_confirmation) {
  {
    const std::lock_guard lock(mutex_);
    confirmation_ = operator_confirmation;
  }
  armed_ = !operator_confirmation.empty();
}

void SafetyGuard::disarm() {
  armed_ = false;
}

std::string SafetyGuard::confirmation() const {
  const std::lock_guard lock(mutex_);
  return confirmation_;
}

void SafetyGuard::request_stop(const std::string& reason) {
  {
    const std::lock_guard lock(mutex_);
    if (stop_reason_.empty()) stop_reason_ = reason;
  }
  stop_ = true;
}

void SafetyGuard::request_stop_from_signal() noexcept {
  stop_from_signal_ = true;
  stop_ = true;
}

std::string SafetyGuard::stop_reason() const {
  const std::lock_guard lock(mutex_);
  if (!stop_reason_.empty()) return stop_reason_;
  return stop_from_signal_.load() ? "Ctrl-C (SIGINT)" : "";
}

void SafetyGuard::resume() {
  {
    const std::lock_guard lock(mutex_);
    stop_reason_.clear();
  }
  stop_from_signal_ = false;
  stop_ = false;
  armed_ = false;
}

std::optional<std::string> SafetyGuard::check_flags() const {
  if (stop_requested())
    return "stop requested (" + stop_reason() + "): resume and confirm again before moving";
  if (!dry_run_ && !armed())
    return std::string("not armed: the operator has not confirmed that the cell is safe to move");
  return std::nullopt;
}

GuardVerdict SafetyGuard::check_home() const {
  GuardVerdict v;
  if (const auto why = check_flags()) {
    v.reason = *why;
    return v;
  }
  v.allowed = true;
  return v;
}

GuardVerdict SafetyGuard::check_move(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                     const MoveSpeed& speed) const {
  GuardVerdict v;
  const auto n = static_cast<Eigen::Index>(model_->actuated.size());
  if (const auto why = check_flags()) {
    v.reason = *why;
    return v;
  }
  if (to.size() != n || !to.allFinite()) {
    v.reason = fmt::format("target must be {} finite actuator readings, got {}", n, vec_text(to));
    return v;
  }
  if (!(limits_.max_speed > 0.0) || !(limits_.max_acceleration > 0.0)) {
    v.reason = "no speed/acceleration limit declared: refusing to move";
    return v;
  }
  if (!(speed.speed > 0.0) || speed.speed > limits_.max_speed) {
    v.reason = fmt::format("speed {:.6g}/s outside (0, {:.6g}/s] (the declared limit)", speed.speed,
                           limits_.max_speed);
    return v;
  }
  if (!(speed.acceleration > 0.0) || speed.acceleration > limits_.max_acceleration) {
    v.reason = fmt::format("acceleration {:.6g}/s^2 outside (0, {:.6g}/s^2] (the declared limit)",
                           speed.acceleration, limits_.max_acceleration);
    return v;
  }
  // The path starts where the controller last confirmed it was; with no reading yet (before
  // the first read) only the target itself can be checked.
  const bool have_start = from.size() == n && from.allFinite();
  const Eigen::VectorXd start = have_start ? from : to;
  double span = 0.0;  // joint units
  for (Eigen::Index i = 0; i < n; ++i)
    span = std::max(span, std::abs(to[i] - start[i]) * joint_per_reading_[i]);
  const double step = limits_.path_step > 0.0 ? limits_.path_step : 1e-3;
  // Bounded, so that a start reading far outside any limit cannot ask for billions of samples
  // (the first sample then refuses it anyway).
  constexpr double kMaxSamples = 1e6;
  if (!(std::ceil(span / step) <= kMaxSamples)) {
    v.reason = fmt::format(
        "the path from {} to {} spans {:.6g} joint units: more than {:.0f} checked samples of "
        "{:.3g}; move in shorter steps",
        vec_text(start), vec_text(to), span, kMaxSamples, step);
    return v;
  }
  const int steps = std::max(1, static_cast<int>(std::ceil(span / step)));
  calib::ClosureSolver solver(*model_, params_);
  Eigen::VectorXd passive;
  const int task_frame = model_->task.frame >= 0 ? model_->task.frame : model_->tool;
  for (int k = 0; k <= steps; ++k) {
    PathSample s;
    s.fraction = static_cast<double>(k) / steps;
    s.readings = start + s.fraction * (to - start);
    for (Eigen::Index i = 0; i < n; ++i) {
      if (s.readings[i] < limits_.actuator_lower[i] - 1e-12 ||
          s.readings[i] > limits_.actuator_upper[i] + 1e-12) {
        v.reason = fmt::format(
            "actuator {} ({}) would reach {:.6g} at {:.0f}% of the path, outside its limits "
            "[{:.6g}, {:.6g}]",
            i, model_->bodies[model_->actuated[static_cast<std::size_t>(i)]].name, s.readings[i],
            100 * s.fraction, limits_.actuator_lower[i], limits_.actuator_upper[i]);
        return v;
      }
    }
    const calib::ClosureResult closure = solver.solve(s.readings, passive);
    if (!closure.ok()) {
      v.reason =
          fmt::format("the robot cannot assemble at {:.0f}% of the path (readings {}): {}",
                      100 * s.fraction, vec_text(s.readings), calib::to_string(closure.status));
      return v;
    }
    // Near a singular configuration the modes meet: a motion through it may leave the true robot
    // on another assembly mode than the model's answer (the answer itself is ambiguous there).
    if (closure.mode.verdict == calib::ModeVerdict::kAmbiguous) {
      v.reason = fmt::format(
          "the path passes too near a singular configuration at {:.0f}% (readings {}), where the "
          "robot could change its assembly mode: {}",
          100 * s.fraction, vec_text(s.readings), closure.mode.describe());
      return v;
    }
    passive = closure.passive;
    s.state = calib::make_joint_state(*model_, params_, s.readings, closure.passive);
    s.tool_pose = calib::frame_pose(*model_, params_, s.state, task_frame);
    const Eigen::Vector3d p = s.tool_pose.translation();
    if ((p.array() < limits_.workspace_min.array()).any() ||
        (p.array() > limits_.workspace_max.array()).any()) {
      v.reason = fmt::format(
          "task frame at ({:.4f}, {:.4f}, {:.4f}) m at {:.0f}% of the path is outside the "
          "declared workspace [{:.4f}, {:.4f}] x [{:.4f}, {:.4f}] x [{:.4f}, {:.4f}]",
          p.x(), p.y(), p.z(), 100 * s.fraction, limits_.workspace_min.x(),
          limits_.workspace_max.x(), limits_.workspace_min.y(), limits_.workspace_max.y(),
          limits_.workspace_min.z(), limits_.workspace_max.z());
      return v;
    }
    if (clearance_) {
      if (const auto why = clearance_(s)) {
        v.reason = fmt::format("path not clear at {:.0f}%: {}", 100 * s.fraction, *why);
        return v;
      }
    }
    v.samples = k + 1;
    if (k == 0 || k == steps) v.path.push_back(std::move(s));
  }
  v.allowed = true;
  return v;
}

}  // namespace robocal::robotio
