#pragma once
// Open-tree forward kinematics, rotation helpers, and the parameter Jacobian through closures.
// Pose and rotation conventions: see mechanism.hpp (poses map frame -> world; rotation
// increments are world-frame small-angle vectors, R' = Exp(w) R).
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <vector>

namespace robocal::calib {

// World poses of every body for a joint state (open tree; closures are not enforced here).
// `poses` is resized to bodies.size().
void body_poses(const Mechanism& model, const Eigen::VectorXd& params, const JointState& state,
                std::vector<Eigen::Isometry3d>& poses);

// World pose of one body frame.
Eigen::Isometry3d frame_pose(const Mechanism& model, const Eigen::VectorXd& params,
                             const JointState& state, int body);

// Rotation vector (axis * angle, angle in [0, pi]) of a rotation matrix: the log map.
Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R);
// Exp map: rotation matrix of a rotation vector.
Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& w);
// Rotation error between two orientations, world frame: log(Ra * Rb^T).
inline Eigen::Vector3d rotation_error(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  return rotation_log(Ra * Rb.transpose());
}

// Closure residual v (constraint_rows() entries) of an open-tree state: for each closure, in
// order, position rows p_a - p_b; rotation rows 0.5 * sum_k (b_k x a_k) (a_k, b_k the columns of
// R_a, R_b; equals the rotation vector of R_a R_b^T to first order) for kPose; for kPositionAxis
// the rows (x_b . z_a, y_b . z_a); for kDistance |p_a - p_b| - length.
Eigen::VectorXd closure_residual(const Mechanism& model, const Eigen::VectorXd& params,
                                 const JointState& state);

// Jacobian of a frame pose with respect to ALL parameters (6 x P), through the closures by the
// implicit-function theorem:
//   df/da = (partial f / partial a) - (partial f / partial theta) * (dv/dtheta)^+ * (dv/da)
// with theta the passive joints. Rows 0-2: d(position)/da in world coordinates; rows 3-5: world
// small-angle rotation w with R(a + da) = Exp(w) R(a). Encoder parameters are included (they act
// through the actuated joints at the given readings). `state` must be a solved state (closure
// residual ~0), e.g. from ClosureSolver; derivatives are exact (analytic).
Eigen::Matrix<double, 6, Eigen::Dynamic> parameter_jacobian(
    const Mechanism& model, const Eigen::VectorXd& params, const JointState& state,
    const Eigen::VectorXd& actuator_readings, int frame);

// frame_pose / parameter_jacobian / frame_jacobians throw std::invalid_argument for an
// out-of-range frame or wrongly sized vectors (programming errors, not data errors).

// Same but also returns d(pose)/d(actuator readings) (6 x A) through the closures, which
// identification needs for actuator-noise propagation.
struct FrameJacobians {
  Eigen::Matrix<double, 6, Eigen::Dynamic> parameters;  // 6 x P
  Eigen::Matrix<double, 6, Eigen::Dynamic> actuators;   // 6 x A (per reading unit)
};
FrameJacobians frame_jacobians(const Mechanism& model, const Eigen::VectorXd& params,
                               const JointState& state, const Eigen::VectorXd& actuator_readings,
                               int frame);

}  // namespace robocal::calib
