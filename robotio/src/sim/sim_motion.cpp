// The simulated controller's true robot: the motion queue with trapezoid timing, stepper
// quantisation, backlash and repeatability noise, the true actuator positions and end-effector
// pose, and the JSONL log that records every motion (the independent record tests read).
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "sim_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace robocal::robotio {

FlangeFrames flange_frames(const calib::Mechanism& model) {
  FlangeFrames f;
  const int tool = model.task.frame >= 0 ? model.task.frame : model.tool;
  f.flange = tool;
  if (tool >= 0) {
    const calib::Body& b = model.bodies[static_cast<std::size_t>(tool)];
    if (b.joint == calib::JointType::kFixed && b.parent >= 0) f.flange = b.parent;
  }
  if (!model.bodies.empty() && model.bodies.front().parent < 0 &&
      model.bodies.front().joint == calib::JointType::kFixed && f.flange != 0)
    f.base = 0;
  return f;
}

std::optional<Eigen::Isometry3d> true_flange_pose(const SimRobot& robot,
                                                  const Eigen::VectorXd& true_readings) {
  const FlangeFrames f = flange_frames(robot.model);
  const calib::ForwardResult fk =
      calib::forward_kinematics(robot.model, robot.truth, true_readings, f.flange);
  if (!fk.closure.ok()) return std::nullopt;
  if (f.base < 0) return fk.pose;
  return calib::frame_pose(robot.model, robot.truth, fk.state, f.base).inverse() * fk.pose;
}

std::string pose_channel_reply(const SimRobot& robot, const Eigen::VectorXd& true_readings,
                               double t, bool moving, long motion) {
  nlohmann::json j;
  j["t"] = t;
  j["moving"] = moving;
  j["motion"] = motion;
  const int frame = robot.model.task.frame >= 0 ? robot.model.task.frame : robot.model.tool;
  const calib::ForwardResult fk =
      calib::forward_kinematics(robot.model, robot.truth, true_readings, frame);
  j["frame"] = robot.model.bodies[static_cast<std::size_t>(frame)].name;
  j["actuators_true"] =
      std::vector<double>(true_readings.data(), true_readings.data() + true_readings.size());
  if (!fk.closure.ok()) {
    j["error"] = std::string("closure: ") + calib::to_string(fk.closure.status);
    return j.dump();
  }
  const Eigen::Vector3d p = fk.pose.translation();
  const Eigen::Quaterniond q(fk.pose.linear());
  j["position"] = {p.x(), p.y(), p.z()};
  j["quaternion_wxyz"] = {q.w(), q.x(), q.y(), q.z()};
  return j.dump();
}

std::vector<long> SimController::Impl::counts_of(const Eigen::VectorXd& readings) const {
  if (options.delta) return delta_counts(*options.delta, readings);
  return axis_counts(robot.axes, readings);
}

Eigen::Vector3d SimController::Impl::nozzle_of(const std::vector<long>& c) const {
  return cartesian_for_counts(*options.delta, c).value_or(Eigen::Vector3d::Zero());
}

double SimController::Impl::units_of(long count, int axis) const {
  return static_cast<double>(count) / robot.axes.steps_per_unit[static_cast<std::size_t>(axis)];
}

void SimController::Impl::write_log(nlohmann::json j) {
  if (log == nullptr) return;
  j["t"] = std::round(t() * 1e6) / 1e6;
  const std::string s = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::fputs(s.c_str(), log);
  std::fputc('\n', log);
  std::fflush(log);
}

void SimController::Impl::start_next_motion(double now) {
  if (queue.empty() || queue.front().start >= 0.0) return;
  Motion& m = queue.front();
  m.from = counts;
  double len2 = 0.0;
  for (int i = 0; i < robot.axes.size(); ++i) {
    const double d =
        units_of(m.to[static_cast<std::size_t>(i)] - m.from[static_cast<std::size_t>(i)], i);
    len2 += d * d;
  }
  // A delta firmware plans feed and acceleration along its Cartesian path.
  m.length = options.delta ? (nozzle_of(m.to) - nozzle_of(m.from)).norm() : std::sqrt(len2);
  m.duration = trapezoid_seconds(m.length, m.feed, m.acceleration);
  m.start = now;
  ++counters.motions;
  std::vector<double> target(m.to.size());
  for (int i = 0; i < robot.axes.size(); ++i)
    target[static_cast<std::size_t>(i)] = units_of(m.to[static_cast<std::size_t>(i)], i);
  write_log({{"ev", "motion_start"},
             {"id", m.id},
             {"ch", m.channel},
             {"line", m.line},
             {"from", m.from},
             {"to", m.to},
             {"target", target},
             {"target_readings", readings_of(m.to)},
             {"length", m.length},
             {"feed", m.feed},
             {"acceleration", m.acceleration},
             {"duration_s", m.duration},
             {"homing", m.homing}});
}

std::vector<double> SimController::Impl::readings_of(const std::vector<long>& c) const {
  if (options.delta) {
    const Eigen::VectorXd r = delta_readings(*options.delta, c);
    return {r.data(), r.data() + r.size()};
  }
  std::vector<double> r(c.size());
  for (int i = 0; i < robot.axes.size(); ++i)
    r[static_cast<std::size_t>(i)] = units_of(c[static_cast<std::size_t>(i)], i) /
                                     robot.axes.unit_factor[static_cast<std::size_t>(i)];
  return r;
}

std::vector<long> SimController::Impl::interpolate(const Motion& m, double now) const {
  double elapsed = now - m.start;
  if (m.stall) elapsed = std::min(elapsed, 0.5 * m.duration);
  const double s = m.length > 0.0
                       ? trapezoid_distance(m.length, m.feed, m.acceleration, elapsed) / m.length
                       : 1.0;
  std::vector<long> c(m.from.size());
  for (std::size_t i = 0; i < c.size(); ++i)
    c[i] = m.from[i] + std::lround(s * static_cast<double>(m.to[i] - m.from[i]));
  return c;
}

void SimController::Impl::finish_motion(const Motion& m, const std::vector<long>& reached,
                                        bool stopped) {
  // Backlash: an axis that reverses loses `backlash` of motion; the physical position lags the
  // counted one by half the backlash against the direction of travel. Repeatability noise is
  // drawn once per move.
  std::normal_distribution<double> noise(0.0, 1.0);
  for (int i = 0; i < robot.axes.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    const long d = reached[k] - m.from[k];
    if (d != 0) last_direction[k] = d > 0 ? 1 : -1;
    physical_offset[i] =
        -0.5 * robot.backlash * last_direction[k] + robot.noise_sigma * noise(noise_rng);
  }
  counts = reached;
  write_log({{"ev", "motion_end"}, {"id", m.id}, {"counts", reached}, {"stopped", stopped}});
}

void SimController::Impl::advance_motion(double now) {
  while (!queue.empty()) {
    start_next_motion(now);
    Motion& m = queue.front();
    if (m.stall || now < m.start + m.duration) {
      counts = interpolate(m, now);
      return;
    }
    const Motion done = m;
    queue.pop_front();
    finish_motion(done, done.to, false);
    if (!queue.empty()) queue.front().start = -1.0;
    start_next_motion(done.start + done.duration);
  }
}

// M410 / M112: motion stops where it is, the queue is dropped.
void SimController::Impl::quick_stop(const std::string& how) {
  const double now = now_seconds();
  if (!queue.empty() && queue.front().start >= 0.0) {
    const Motion m = queue.front();
    finish_motion(m, interpolate(m, now), true);
  }
  queue.clear();
  ++counters.stops;
  write_log({{"ev", "stop"}, {"cmd", how}, {"counts", counts}});
}

Eigen::VectorXd SimController::Impl::true_readings(double now) const {
  std::vector<long> c = counts;
  if (!queue.empty() && queue.front().start >= 0.0) c = interpolate(queue.front(), now);
  const std::vector<double> r = readings_of(c);
  Eigen::VectorXd out(static_cast<Eigen::Index>(r.size()));
  for (std::size_t i = 0; i < r.size(); ++i)
    out[static_cast<Eigen::Index>(i)] = r[i] + physical_offset[static_cast<Eigen::Index>(i)];
  return out;
}
}  // namespace robocal::robotio
