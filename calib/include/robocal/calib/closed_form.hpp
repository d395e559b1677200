#pragma once
// Closed-form kinematics of the idealised parallel robots (Mechanism::closed_form). They are
// exact for the nominal geometry and serve as seeds (and as the speed floor in benchmarks); the
// generic tree + closure model is what handles calibrated, perturbed geometry.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>

#include <optional>

namespace robocal::calib {

// Rotary Delta. Actuator angle theta_i (joint value) turns arm i down from the horizontal:
// elbow_i = Rz(phi_i) * [r_b + n cos(theta_i), 0, -n sin(theta_i)];
// ||elbow_i - (T + Rz(phi_i) [r_n, 0, 0])|| = m. Returns the plate centre T on the branch below
// the elbows (the intended assembly mode), nullopt when the spheres do not intersect.
std::optional<Eigen::Vector3d> delta_forward(const ClosedFormSpec& spec,
                                             const Eigen::Vector3d& theta);
// Inverse: the actuator angles for plate centre T, choosing per arm the elbow-out solution;
// nullopt when unreachable.
std::optional<Eigen::Vector3d> delta_inverse(const ClosedFormSpec& spec, const Eigen::Vector3d& T);

// Linear delta / Gantry-Tau (three rails): ||A_i + q_i v_i - (T + c_i)|| = L_i.
std::optional<Eigen::Vector3d> rails_forward(const ClosedFormSpec& spec, const Eigen::Vector3d& q);
// Chooses per rail the root with T - A_i on the spec's branch side (smaller q for branch_sign<0).
std::optional<Eigen::Vector3d> rails_inverse(const ClosedFormSpec& spec, const Eigen::Vector3d& T);

// Dispatch on spec.kind: task-frame position for actuator joint values q, or the inverse.
std::optional<Eigen::Vector3d> closed_form_forward(const ClosedFormSpec& spec,
                                                   const Eigen::VectorXd& q);
std::optional<Eigen::VectorXd> closed_form_inverse(const ClosedFormSpec& spec,
                                                   const Eigen::Vector3d& T);

}  // namespace robocal::calib
