#include "robocal/calib/frame_placement.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"

#include <Eigen/Dense>

#include <numbers>
#include <stdexcept>
#include <vector>

namespace robocal::calib {

double set_fixed_frame_pose(const Mechanism& model, Eigen::VectorXd& params, int body,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::Isometry3d& world_T_desired) {
  std::vector<int> own;
  for (int i = 0; i < static_cast<int>(model.parameters.size()); ++i)
    if (model.parameters[static_cast<std::size_t>(i)].body == body) own.push_back(i);
  if (own.empty()) throw std::runtime_error(model.bodies.at(body).name + " has no parameters");

  auto pose_error = [&](const Eigen::VectorXd& p, Eigen::Matrix<double, 6, 1>* e) {
    const auto fk = forward_kinematics(model, p, actuator_readings, body);
    if (!fk.closure.ok()) return false;
    e->head<3>() = fk.pose.translation() - world_T_desired.translation();
    e->tail<3>() = rotation_error(fk.pose.linear(), world_T_desired.linear());
    return true;
  };
  Eigen::Matrix<double, 6, 1> e;
  // A target turned by about a half turn from the frame: there the rotation error's axis flips,
  // the central differences below straddle the flip and Gauss-Newton goes nowhere ("remaining
  // error 3.141593"), so the frame is first placed half way there (a quarter turn).
  if (!pose_error(params, &e)) throw std::runtime_error("closure failed while placing a frame");
  if (e.tail<3>().norm() > 0.75 * std::numbers::pi) {
    const auto fk = forward_kinematics(model, params, actuator_readings, body);
    Eigen::Isometry3d half_way = world_T_desired;
    half_way.linear() = Eigen::Quaterniond(fk.pose.linear())
                            .slerp(0.5, Eigen::Quaterniond(world_T_desired.linear()))
                            .toRotationMatrix();
    set_fixed_frame_pose(model, params, body, actuator_readings, half_way);
  }
  for (int iteration = 0; iteration < 30; ++iteration) {
    if (!pose_error(params, &e)) throw std::runtime_error("closure failed while placing a frame");
    if (e.norm() < 1e-13) break;
    Eigen::MatrixXd J(6, static_cast<Eigen::Index>(own.size()));
    for (std::size_t k = 0; k < own.size(); ++k) {
      const double h = 1e-7;
      Eigen::VectorXd plus = params, minus = params;
      plus[own[k]] += h;
      minus[own[k]] -= h;
      Eigen::Matrix<double, 6, 1> ep, em;
      if (!pose_error(plus, &ep) || !pose_error(minus, &em))
        throw std::runtime_error("closure failed while placing a frame");
      J.col(static_cast<Eigen::Index>(k)) = (ep - em) / (2 * h);
    }
    // Minimum-norm step: redundant parameters of the frame stay where they are.
    const Eigen::VectorXd step = J.completeOrthogonalDecomposition().solve(-e);
    for (std::size_t k = 0; k < own.size(); ++k)
      params[own[k]] += step[static_cast<Eigen::Index>(k)];
  }
  pose_error(params, &e);
  return e.norm();
}

std::vector<std::pair<std::string, double>> mounted_frame_parameters(
    const Mechanism& model, const Eigen::VectorXd& params, int body,
    const Eigen::Isometry3d& frame_T_offset) {
  const Body& b = model.bodies.at(static_cast<std::size_t>(body));
  bool in_loop = false;
  for (const Closure& c : model.closures)
    in_loop = in_loop || (c.body_a >= body && c.body_a < b.subtree_end) ||
              (c.body_b >= body && c.body_b < b.subtree_end);
  if (b.joint != JointType::kFixed || in_loop)
    throw std::invalid_argument("'" + b.name + "' is " +
                                (in_loop ? "part of a closed loop" : "a moving joint") +
                                ": a target offset cannot be expressed by its parameters; mount "
                                "the target on a fixed tool frame outside every loop");
  Eigen::VectorXd home_q(static_cast<Eigen::Index>(model.actuated.size()));
  for (std::size_t i = 0; i < model.actuated.size(); ++i)
    home_q[static_cast<Eigen::Index>(i)] = model.bodies[model.actuated[i]].home;
  const Eigen::VectorXd readings = readings_from_joint_values(model, params, home_q);
  const auto fk = forward_kinematics(model, params, readings, body);
  if (!fk.closure.ok())
    throw std::invalid_argument("'" + b.name + "': the home configuration does not close");
  Eigen::VectorXd placed = params;
  double residual = 0.0;
  try {
    residual = set_fixed_frame_pose(model, placed, body, readings, fk.pose * frame_T_offset);
  } catch (const std::runtime_error& e) {
    throw std::invalid_argument("'" + b.name + "': " + e.what());
  }
  if (!(residual <= 1e-9))
    throw std::invalid_argument("'" + b.name +
                                "': its parameters cannot reach the target's offset "
                                "(remaining error " +
                                std::to_string(residual) + ")");
  std::vector<std::pair<std::string, double>> values;
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (model.parameters[i].body == body)
      values.emplace_back(model.parameters[i].name, placed[static_cast<Eigen::Index>(i)]);
  return values;
}

}  // namespace robocal::calib
