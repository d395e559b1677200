#include "robocal/robotio/native_delta.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <optional>

namespace robocal::robotio {

CarriageFrame native_frame(const DeltaGeometry& firmware, const calib::Mechanism& model,
                           double steps_per_mm, GeometryChoice choice, const std::string& device,
                           std::vector<std::string>& disagreements) {
  const RobotFileDelta file = robot_file_delta(model);
  if (!file.problem.empty()) throw LinkError(device, file.problem);
  CarriageFrame frame;
  frame.geometry = firmware;
  frame.endstop_reading = file.endstop_reading;
  frame.steps_per_mm = steps_per_mm;
  disagreements = geometry_disagreements(frame.geometry, file);
  if (!disagreements.empty() && choice == GeometryChoice::kAsk) {
    std::string list;
    for (const std::string& d : disagreements) list += "\n  " + d;
    throw GeometryDisagreement(
        device, fmt::format("the firmware's delta geometry disagrees with the robot file '{}' "
                            "(nothing moved):{}\nchoose which to trust: the firmware's or the "
                            "robot file's (--firmware-geometry firmware|robot-file)",
                            model.name, list));
  }
  return frame;
}

std::vector<Eigen::VectorXd> native_waypoints(const Eigen::VectorXd& from,
                                              const Eigen::VectorXd& to,
                                              const Eigen::VectorXd& joint_per_reading,
                                              double segment) {
  // The firmware moves straight in its Cartesian frame, the guard checked the straight line in
  // actuator space: points of that line close together keep the two within the chord's sag
  // (5 mm of carriage travel on 270 mm rods: about 10 um).
  const bool known = from.size() == to.size();
  const double joint = known ? (to - from).cwiseProduct(joint_per_reading).norm() : 0.0;
  const int n = known ? std::max(1, static_cast<int>(std::ceil(joint / segment))) : 1;
  std::vector<Eigen::VectorXd> points;
  for (int k = 1; k <= n; ++k)
    points.push_back(k == n ? to
                            : Eigen::VectorXd(from + (to - from) * (static_cast<double>(k) / n)));
  return points;
}

std::vector<std::string> native_move_gcodes(const CarriageFrame& frame, const Eigen::VectorXd& from,
                                            const Eigen::VectorXd& to, const MoveSpeed& speed,
                                            const Eigen::VectorXd& joint_per_reading,
                                            double segment, const std::string& device) {
  std::vector<std::string> out;
  const bool known = from.size() == to.size();  // unknown start: one move at the plain feed
  Eigen::VectorXd previous = known ? from : to;
  std::optional<Eigen::Vector3d> at =
      known ? cartesian_for_counts(frame, delta_counts(frame, from)) : std::nullopt;
  for (const Eigen::VectorXd& point : native_waypoints(from, to, joint_per_reading, segment)) {
    const std::vector<long> counts = delta_counts(frame, point);
    if (!firmware_can_command(frame, counts))
      throw MotionRefused(fmt::format(
          "move refused: the firmware's delta kinematics cannot command carriage readings "
          "({:.6f}, {:.6f}, {:.6f}) m on the way (a carriage below the nozzle): nothing was sent",
          point[0], point[1], point[2]));
    const std::optional<Eigen::Vector3d> xyz = cartesian_for_counts(frame, counts);
    if (!xyz)
      throw LinkError(
          device, fmt::format("the firmware's delta model ({}) cannot reach carriage readings "
                              "({:.6f}, {:.6f}, {:.6f}) m: its rods do not meet there",
                              to_string(frame.geometry.firmware), point[0], point[1], point[2]));
    // The firmware's feed is along its Cartesian path: scaled per segment so the segment takes
    // as long as `speed` along the joints.
    const double joint = (point - previous).cwiseProduct(joint_per_reading).norm();
    const double cartesian = at ? (*xyz - *at).norm() : 1000.0 * joint;
    const double feed = joint > 0.0 ? speed.speed * cartesian / joint * 60.0 : speed.speed * 6e4;
    out.push_back(fmt::format("G1 X{:.5f} Y{:.5f} Z{:.5f} F{:.3f}", xyz->x(), xyz->y(), xyz->z(),
                              std::max(feed, 1e-3)));
    previous = point;
    at = xyz;
  }
  return out;
}

double native_gcode_per_joint(const CarriageFrame& frame, const Eigen::VectorXd& from,
                              const Eigen::VectorXd& to, const Eigen::VectorXd& joint_per_reading) {
  if (from.size() != to.size()) return 1000.0;
  const auto a = cartesian_for_counts(frame, delta_counts(frame, from));
  const auto b = cartesian_for_counts(frame, delta_counts(frame, to));
  const double joint = (to - from).cwiseProduct(joint_per_reading).norm();
  if (a && b && joint > 0.0 && (*b - *a).norm() > 0.0) return (*b - *a).norm() / joint;
  return 1000.0;
}

double native_expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                               const MoveSpeed& speed, const Eigen::VectorXd& joint_per_reading,
                               double segment) {
  double s = 0.0;
  Eigen::VectorXd previous = from;
  for (const Eigen::VectorXd& point : native_waypoints(from, to, joint_per_reading, segment)) {
    const double length = previous.size() == point.size()
                              ? (point - previous).cwiseProduct(joint_per_reading).norm()
                              : 0.0;
    s += trapezoid_seconds(length, speed.speed, speed.acceleration);
    previous = point;
  }
  return s;
}

}  // namespace robocal::robotio
