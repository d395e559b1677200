#include "robocal/calib/base_frame.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_placement.hpp"

#include <Eigen/Geometry>

#include <variant>

namespace robocal::calib {

BaseFrameFit fit_base_frame(const Mechanism& model, Eigen::VectorXd& params, int frame,
                            const std::vector<PoseMeasurement>& poses) {
  BaseFrameFit out;
  std::vector<Eigen::Vector3d> predicted, measured;
  for (const auto& pose : poses) {
    if (pose.observations.empty()) continue;
    const auto fk = forward_kinematics(model, params, pose.actuators, frame);
    const auto* obs = std::get_if<PoseObservation>(&pose.observations.at(0));
    if (!fk.closure.ok() || obs == nullptr) continue;
    predicted.emplace_back(fk.pose.translation());
    measured.push_back(obs->measured_position);
  }
  out.poses = predicted.size();
  if (predicted.size() < 3) return out;
  Eigen::Matrix3Xd P(3, static_cast<Eigen::Index>(predicted.size())), M(3, P.cols());
  for (std::size_t i = 0; i < predicted.size(); ++i) {
    P.col(static_cast<Eigen::Index>(i)) = predicted[i];
    M.col(static_cast<Eigen::Index>(i)) = measured[i];
  }
  out.world_T_base = Eigen::Isometry3d(Eigen::umeyama(P, M, false));
  const int root = 0;  // the first body hangs from the world: the base frame
  const auto& q0 = poses[0].actuators;
  const auto root_pose = forward_kinematics(model, params, q0, root).pose;
  set_fixed_frame_pose(model, params, root, q0, out.world_T_base * root_pose);
  out.placed = true;
  return out;
}

}  // namespace robocal::calib
