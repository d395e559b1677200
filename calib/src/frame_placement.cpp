#include "robocal/calib/frame_placement.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"

#include <Eigen/Dense>

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

}  // namespace robocal::calib
